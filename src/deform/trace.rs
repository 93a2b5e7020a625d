//! Ray tracing deforming surfel objects, per frame (Adams et al. §4.1.2, §4.2, §4.4): closest
//! hit and any hit, with three update modes:
//!
//! - `Naive`: every frame, all surfels are deformed (Eq. 1) and the hierarchy is rebuilt
//!   from scratch (median split + miniball), as in the paper's "no coherence" curve.
//! - `Lazy`: the hierarchy built once for the undeformed object is updated only where rays
//!   go: a node's centre and radius (Eq. 3–4, 9) are computed the first time it is needed in
//!   a frame; once both children are current the parent's radius is tightened with Eq. 11;
//!   surfels (and their MLS neighbours) are deformed when a ray reaches their leaf.
//! - `LazyCache`: `Lazy` plus the per-ray cache of §4.2.2: the leaf of the closest hit of
//!   slot k (e.g. pixel k) in the previous frame is tested first, so its hit bounds the
//!   traversal from the root. Two deviations as options: `cache_up` caches an ancestor of
//!   that leaf, and `cache_climb` (not in the paper) climbs from a cached node that holds no
//!   hit, searching each ancestor's other child, until a hit is found; the traversal from
//!   the root then skips the climb's top node. Under this motion a surfel leaves its ray
//!   within a frame (the paper's leaf cache hits on 0.4–4 % of lookups), and a fixed
//!   ancestor is too small for fast parts and too large for still ones; the climb stops at
//!   the smallest node that holds the hit, whatever the motion was.
//!
//!   **Cache gate (deviation, stop 70; `TraceParams::cache_gate`, `animate --cache-gate`).**
//!   Under the default front-to-back descent the cache is looked up only while at least a
//!   quarter of its lookups hit: a frame whose lookups (≥ 256 of them) hit less closes it,
//!   and a closed cache is probed every [`CACHE_PROBE`] frames (the frame before refreshes
//!   the slots), reopening if the probe hits enough. Front-to-back descent reaches the near
//!   hit that a cached node would bound the ray with by itself, so the cache saves nothing
//!   there, and under this motion its leaves hit on 0.7–7 % of lookups; its slot loads and
//!   stores, prefetches and scalar searches made `lazy-cache` 2–4 % slower than `lazy` on
//!   all four sequences (stop 70 bench). Gated, `elastic-balls` lazy-cache runs 3.4 %
//!   faster, as fast as `lazy`. Hits alone do not make the cache pay: `bend`'s leaves hit on
//!   a third of the lookups over its first swing, the gate stayed open, and the lookups cut
//!   no sphere or leaf test (3.979 M a frame against `lazy`'s 3.978 M) while costing 4.9 %
//!   of `render_frame`'s instructions. So since stop 86 an open cache also skips its lookups
//!   every [`CACHE_PROBE`] frames (keeping its slots), and closes unless the frame before,
//!   with lookups, took `CACHE_GATE_SAVING` (5 %) fewer sphere and leaf tests than this one
//!   without; a closed cache's probe reopens it only if it hits often enough and takes that
//!   many fewer tests than the frame before it. (A still frame repeated, every lookup a hit:
//!   3.5 % fewer tests, not enough.) `cache_gate = 0` looks up every frame, as the paper
//!   does; the unordered descent (the paper's, where the cache's bound pays) is never
//!   gated. Same images either way.
//!
//! - `Auto` (not in the paper; the heuristic its §6 asks for): per frame `Naive` or `Lazy`,
//!   whichever cost less when last tried ([`AutoPick`]; the caller reports frame times with
//!   [`DeformTracer::end_frame`]).
//! - `Refit` (not in the paper; the alternative a user would try today): an obvhs BVH2 (PLOC,
//!   up to 8 surfels per leaf) built once over the undeformed surfels; every frame all
//!   surfels are deformed and the boxes refitted bottom-up (`Bvh2::refit_all`). Leaf boxes
//!   bound each surfel's leaf *ball* (not just its ellipse), so an MLS hit, which lies in its
//!   leaf ball, is never culled: hits equal the other modes'. Box tests are counted as
//!   `sphere_tests` (bounding-volume tests).
//!
//! Shadow rays (`occluded`) use the §4.4 optimisation: at a hit parent, a child that is
//! already current is visited before one that would need an update; any accepted hit ends the
//! ray. *Deviation:* shadow rays do not apply Eq. 11 (§4.4 tightens a node at any revisit);
//! only the closest-hit descents do (`child_spheres`), and shadow rays use the spheres they
//! left. No effect on hits, only on sphere tests. Accepted hits pass the clipping test of
//! §4.3 against the two nearest surfels of every partner collection.
//!
//! **Concurrency and determinism.** `intersect` and `occluded` take `&self` and may run on any
//! number of threads. Lazy state lives in atomics: a node or surfel carries the frame stamp
//! of its last update; a surfel's value is a pure function of the frame, so racing writers
//! store identical bits (release/acquire on the stamp publishes them). A node's sphere is
//! published once per frame and then only replaced by smaller ones (Eq. 11, which may move
//! the centre), under a per-node try-lock and a radius-before-centre read order that keeps
//! every sphere a reader can assemble conservative (`NodeSlot`). The closest hit is a pure function of the frame and the ray: every leaf ball lies
//! inside all its ancestors' balls and an MLS hit must lie inside its leaf ball, so culling
//! never removes the closest accepted hit, whatever radii the inner nodes have when a ray
//! tests them; ties are broken by (instance, surfel). Images are therefore identical for any
//! thread count and in all update modes. Work counters (sphere tests, nodes updated) may vary
//! slightly between multi-threaded runs, because which rays see a tightened radius depends
//! on timing; single-threaded they are deterministic.
//!
//! Instances of the same object share its precomputed data (§6). A ray finds the instances
//! along it in a sphere tree over their root spheres, rebuilt in `begin_frame` (not in the
//! paper: [`super::top`]; `TraceParams::instance_tree = false` tests every root, the
//! candidates' roots 8 per step with the f32x8 sphere kernel). A packet in a scene of 5–64
//! instances instead bounds its rays by one cone and tests all instance spheres against it,
//! eight per step ([`super::top::PacketCone`], stop 85).
//!
//! **Packets (the user's design card: sphere tests for several rays per SIMD step).**
//! `intersect_x8` / `occluded_x8` trace up to eight rays together (`lodtrace animate` uses
//! 4×2 pixel tiles and then their shadow rays): a node's sphere is fetched, and lazily
//! updated, once for the packet and tested against all its active rays in one
//! [`RayPacketX8`] step; a leaf's surfel is fetched once and its ellipse tested against the
//! active rays in one step too (`RayPacketX8::ellipse`, bit-identical to `ellipse_hit` per
//! lane), the MLS iteration then runs ray by ray. Each ray gets exactly the hit of the
//! single-ray path (the argument above does not depend on the visiting order). Per frame
//! this is 1.5–2.1× faster than ray by ray, mostly from the shared node fetch and update.
//! The packet paths allocate nothing per packet (`PacketScratch`). The packet shadow rays
//! (stop 47) test a node's two children together when both are current (always, in `naive`):
//! the two slot loads and tests overlap instead of waiting one behind the other; otherwise
//! they keep §4.4's order, one child at a time. They need only a hit mask, so they use the
//! square-root-free segment test `RayPacketX8::test_any`. Together: 4–8 % off a `lazy-cache`
//! frame, 1–4 % off a `naive` one (BENCHMARKS.md, "Stop 47").
//!
//! **Nearest ellipse (deviation; `TraceParams::nearest_ellipse`, on by default; `animate
//! --nearest mls` restores the paper's rule).** The paper runs the MLS iteration (§4.2.1) at
//! every leaf whose ellipse the ray hits and keeps the nearest result. Splats overlap 4–5
//! deep on a visible surface, so a closest-hit ray ran about five iterations (each deforming
//! and reading 16 neighbours) to find one point. Here the closest hit is the MLS hit
//! iterated from the nearest ellipse hit (smallest `t0`, ties by (instance, surfel)) among
//! those whose iteration is accepted. A traversal pass only looks for the nearest ellipse
//! hit (`Rule::Deferred`: culling by its `t0`, which lies in the leaf ball as an MLS hit
//! does, so the argument above still holds) and iterates it after the pass; if that is
//! rejected (on `armadillo-ball` for 16 % of the rays that hit, mostly grazing ones), a
//! second pass iterates every ellipse hit behind it that beats the best so far
//! (`Rule::AboveFloor`). The hit is still a function of the ray and the frame alone, so
//! modes, packets and thread counts agree bit for bit. Surfels of clipped collections
//! (§4.3: the heads) keep the paper's rule, ordered by their MLS `t`: most of their ellipse
//! hits end clipped, and each rejection would cost the ray a pass. The rule takes another
//! splat's iterate of the same sheet, and those agree to the MLS tolerance, except for
//! grazing rays, where the iteration from the nearest splat may settle on the sheet's far
//! crossing (test `nearest_ellipse_finds_the_surface_of_every_splat`). Where a clipped and an
//! unclipped surface meet within a splat's sag, comparing the one's MLS `t` with the
//! other's `t0` may order them wrongly; no built-in sequence has both. `armadillo-ball`,
//! primary rays, frame 7: 116 k → 25 k MLS runs, 7 % more sphere tests.
//!
//! **Early clip (deviation, stop 52; `TraceParams::clip_early`).** An ellipse hit of a
//! clipped surface whose surfel's whole leaf ball lies more than its radius in front of both
//! clipping neighbours' planes is rejected before the MLS iteration (`DeformTracer::ball_clipped`):
//! the iterate would lie in that ball and be clipped. Same hits; `heads` runs half the MLS
//! iterations. (Taking the nearest-ellipse rule for clipped surfaces as well, with such
//! candidates skipped, halved them again but cost as much in extra passes: not kept.)
//!
//! **Subtree refit (deviation).** The first visit of a node over at most
//! `TraceParams::exact_below` surfels (default 4096) bounds its whole subtree from the
//! deformed surfels (`refit_subtree`: the box centre of the leaf balls, the exact reach)
//! instead of by Eq. 9 node by node; 0 restores the paper's rule. Up to stop 41 this applied
//! node by node to nodes of ≤ 64 surfels (centre the mean); a subtree at once costs
//! O(m log m) and at 512×384 the rays deform 93–100 % of the surfels anyway. Sphere tests
//! per frame (lazy-cache, 16 frames, bench mean): `armadillo-ball` 9.35 M → 8.05 M, `bend`
//! 2.22 M → 1.87 M, `elastic-balls` 19.2 M → 15.3 M (root ratio 1.75 → 1.30); lazy-cache ÷
//! naive in one run 1.57 / 1.47 / 1.36 / 1.41× → 1.66 / 1.77 / 1.61 / 1.47× (`armadillo-ball`,
//! `bend`, `heads`, `elastic-balls`; README, "Subtree refit").
//!
//! *Small objects* (stop 44): an object of at most 2·`exact_below` surfels is refitted whole
//! at its root. Otherwise its root, the one node every ray that reaches it tests and the node
//! the instance tree is built over (at `begin_frame`, which now computes the roots in
//! parallel), kept its Eq. 9 sphere around two exact children: `elastic-balls`' 40 balls of
//! 6,000 surfels, root radius ratio ≈ 1.3, 12 % more sphere tests than with exact roots.
//!
//! *Leaf spheres live with their surfels* (stop 48): a leaf's sphere is its surfel's leaf
//! ball, stored in the surfel's slot when the surfel is deformed (§4.1.2 updates a leaf from
//! its surfel), so the node slots hold inner nodes only and a refit publishes half as many
//! nodes (each under the node's sequence lock). The refit also prefetches the surfel and node
//! slots it is about to write. Whole-object refit (`elastic-balls`, one thread) −7 %, lazy
//! frames 0–9 % faster (BENCHMARKS.md, "Stop 48").
//!
//! *Cheaper refits* (stop 62): the whole-object refits that `begin_frame` starts (one task
//! per instance, before any ray) publish their nodes without the sequence lock, and so do
//! the refits during the rays for nodes that every writer writes with the same values
//! (`NodeState::publish`); `max_reach_x8` ends on a masked step instead of a lane-by-lane
//! one; the rest axes are precomputed; Eq. 1's sum is fused where the build has FMA. A
//! whole-object refit (`elastic-balls`) takes 17 % fewer instructions, and its update
//! 24 → 19 ms per frame (BENCHMARKS.md, "Stop 62").
//!
//! *Overlapped misses* (stop 66). The lazy traversals wait on memory, not on arithmetic:
//! perf on `heads` put about half of `intersect_x8`'s samples on the first use of a child's
//! stamp, the right child's slot (far away in pre-order) the most. Each stamp check is a
//! branch, and a child's load did not start before its sibling's branch had resolved. So a
//! node's right child's slot (or its surfel's) is prefetched before the left child's is read
//! (`prefetch_node`, closest and shadow rays); an MLS iteration requests its 16 neighbours'
//! slots before it reads the first (both modes); and a packet's cache lookups, three
//! dependent loads per ray, are staged so each stage's eight loads overlap
//! (`prefetch_cached`: without it the §4.2.2 cache, which rarely hits under front-to-back
//! traversal, made `lazy-cache` 3–8 % slower than `lazy`). Same images; times in
//! BENCHMARKS.md, "Stop 66".
//!
//! *Compact balls* (stop 67). A subtree refit also writes every sphere it computes, leaves
//! included, into a 16-byte `Ball` per node in pre-order (the static tree's layout). A
//! current inner node of at most `DeformTracer::compact_max` surfels (64) was refitted
//! whole before it was published, so the packet traversals read its children from the
//! balls: no stamp check, sequence lock or branch per child, and a leaf child's sphere no
//! longer costs its surfel's 64-byte line (which only a leaf test needs). Below that size
//! a lazy traversal reads the same bytes per node as the naive tree's. The refit also
//! prefetches Eq. 1's inputs of the surfels it is about to deform (`prefetch_surfel_inputs`:
//! perf put two thirds of `deform_surfel`'s samples on those four loads). Same spheres,
//! same sphere tests, same images.
//!
//! *Nothing loaded that the parent knows* (stop 68). The packet traversals carry each
//! node's surfel count on their stacks ([`Topology::split`]: a child's count, kind and
//! right child follow from its parent's), so they no longer load `count` per node (both
//! modes), and a flag for "inside a complete subtree", so below the first complete node
//! no claim is read either (lazy modes). There each hit inner child's far grandchild ball
//! is requested a level ahead. perf had put a quarter of `intersect_x8`'s samples on the
//! two ball loads and a twentieth on the claim's. Same images, same sphere tests.

use super::displace::{deform_point, DeformField, DeformedSurfel};
use super::miniball::miniball;
use super::mls::{clipped_by, ellipse_hit, mls_intersect_x8, MlsNbr, MlsOutcome, MlsParams, MAX_NBR};
use super::object::{SurfelObject, NO_NBR};
use super::top::{PacketCone, TopTree};
use super::tree::{
    child_bound, leaf_sphere, max_reach_x8, sphere_test_1, sphere_test_spheres, RayPacketX8, Topology, LEAF, RADIUS_PAD, REACH_PAD,
};
use super::DeformError;
use crate::baseline::accel::Ray;
use crate::core::stats::{Counter, Counters};
use glam::{Vec3, Vec3A};
use obvhs::{aabb::Aabb, bvh2::Bvh2};
use rayon::prelude::*;
use std::sync::atomic::{AtomicU32, AtomicU64, Ordering::*};
use std::sync::Arc;
use std::time::Instant;
use wide::{f32x8, u32x8};

/// How the hierarchy follows the deformation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum UpdateMode {
    Naive,
    Lazy,
    LazyCache,
    Refit,
    /// Per frame either `Naive` or `Lazy`, whichever cost less when last tried (the paper's
    /// §6: "one might want to devise heuristics to decide whether to use lazy updating or to
    /// perform a (full) sphere hierarchy update"); see [`AutoPick`].
    Auto,
}

impl UpdateMode {
    pub const ALL: [UpdateMode; 5] = [UpdateMode::Naive, UpdateMode::Lazy, UpdateMode::LazyCache, UpdateMode::Refit, UpdateMode::Auto];
    pub fn name(self) -> &'static str {
        match self {
            UpdateMode::Naive => "naive",
            UpdateMode::Lazy => "lazy",
            UpdateMode::LazyCache => "lazy-cache",
            UpdateMode::Refit => "refit",
            UpdateMode::Auto => "auto",
        }
    }
}

/// `UpdateMode::Auto`'s choice between a rebuild (naive) and the lazy update, frame by frame
/// (not in the paper, which names the question in §6). The rebuild's cost does not depend on
/// the rays, the lazy frame's extra ray cost does (BENCHMARKS.md, "Speed-up against
/// the image size", stop 37), so which one wins depends on the image and the motion: each is tried once, then
/// the one whose last frame (as reported by [`DeformTracer::end_frame`]) was cheaper is used,
/// and the other is tried again so that a changing deformation can flip the choice: after
/// [`AutoPick::PROBE`]·r² frames, where r ≥ 1 is the loser's cost over the winner's (at
/// most [`AutoPick::MAX_PROBE`] frames), which keeps the probes' extra cost, (r − 1)/(PROBE·r²)
/// of a frame, under 1/32 of a frame while r ≤ 2.8 ((r − 1)/64 beyond). Without reports it stays with the lazy update after the
/// first two frames and still probes the rebuild every `PROBE` frames.
#[derive(Clone, Copy, Debug, Default)]
pub struct AutoPick {
    /// Last reported seconds of a naive and of a lazy frame.
    cost: [Option<f64>; 2],
    tried: [bool; 2],
    /// Whether the current frame rebuilds.
    naive: bool,
    /// Frames since the mode not chosen was last tried.
    since: u32,
}

impl AutoPick {
    /// The other mode is tried again after this many frames times the squared cost ratio.
    pub const PROBE: u32 = 8;
    /// ... but at least this often.
    pub const MAX_PROBE: u32 = 64;

    /// Whether the next frame rebuilds.
    fn pick(&mut self) -> bool {
        let naive = if !self.tried[0] {
            true
        } else if !self.tried[1] {
            false
        } else {
            let (best_naive, r) = match self.cost {
                [Some(n), Some(l)] => (n < l, if n < l { l / n.max(1e-9) } else { n / l.max(1e-9) }),
                _ => (false, 1.0),
            };
            let every = (Self::PROBE as f64 * r * r).min(Self::MAX_PROBE as f64) as u32;
            self.since += 1;
            if self.since >= every {
                self.since = 0;
                !best_naive
            } else {
                best_naive
            }
        };
        self.tried[naive as usize ^ 1] = true;
        self.naive = naive;
        naive
    }

    fn record(&mut self, seconds: f64) {
        if seconds.is_finite() && seconds >= 0.0 {
            self.cost[self.naive as usize ^ 1] = Some(seconds);
        }
    }
}

impl std::str::FromStr for UpdateMode {
    type Err = DeformError;
    fn from_str(s: &str) -> Result<Self, DeformError> {
        match s {
            "naive" => Ok(UpdateMode::Naive),
            "lazy" => Ok(UpdateMode::Lazy),
            "lazy-cache" | "lazycache" | "cache" => Ok(UpdateMode::LazyCache),
            "refit" => Ok(UpdateMode::Refit),
            "auto" => Ok(UpdateMode::Auto),
            _ => Err(DeformError::Invalid(format!("unknown update mode '{s}' (naive, lazy, lazy-cache, refit, auto)"))),
        }
    }
}

/// Tracer parameters. The defaults are the paper's rules plus the deviations the module docs
/// describe (support stretch, ordered descent, re-centred bounds, subtree refits, instance
/// tree, nearest ellipse, early clip, cache gate); each switch turns one off for ablations.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TraceParams {
    pub mls: MlsParams,
    /// Factor out the optimal rigid transform (§4.1.3).
    pub factor_rigid: bool,
    /// Tighten parents with the child bound (Eq. 11).
    pub eq11: bool,
    /// Shadow rays visit an already updated child first (§4.4).
    pub shadow_updated_first: bool,
    /// The MLS support grows with the local stretch bound, at most by this factor.
    pub max_support_stretch: f32,
    /// Per-ray cache (LazyCache): cache the ancestor this many levels above the leaf of the
    /// closest hit (0 = the leaf itself, the paper's choice; see module docs).
    pub cache_up: u32,
    /// Per-ray cache (LazyCache): when the cached node yields no hit, climb from it towards
    /// the root, searching each ancestor's other child, until one does (see
    /// `search_cached_node`). Off: the paper's single cached node.
    pub cache_climb: bool,
    /// Visit the nearer child first (by sphere entry). Off: always the left child first.
    pub ordered: bool,
    /// Take the smaller of the paper's Eq. 9 bound and the re-centred bound (see `tree`);
    /// off = the paper's bound alone.
    pub recentred_bound: bool,
    /// In the re-centred bound, also factor out each node's own rotation (the paper's §6
    /// "hierarchical approach" to the rigid transform, per node; see `tree`).
    pub node_rotation: bool,
    /// The first visit of an inner node over at most this many surfels (≤
    /// [`MAX_EXACT_BELOW`]) bounds it and its whole subtree from their deformed surfels'
    /// leaf balls (Eq. 11 taken down to the leaves) instead of by Eq. 9 node by node; 0 = Eq.
    /// 9 everywhere (the paper's rule when `recentred_bound`, `node_rotation` and
    /// `recentre_eq11` are off too: `animate --bound paper`). See [`DeformTracer`]'s `refit_subtree`.
    pub exact_below: u32,
    /// Eq. 11 with the centre moved to the smallest sphere around both children (see
    /// `tighten`); off: the paper's Eq. 11 around the node's Eq. 3 centre.
    pub recentre_eq11: bool,
    /// Find the instances along a ray through a sphere tree over their roots, rebuilt every
    /// frame ([`super::top`], not in the paper); off: every ray tests every root. Same images.
    pub instance_tree: bool,
    /// The closest hit is the MLS hit started from the nearest ellipse hit (deviation, see
    /// the module docs: one MLS iteration per ray instead of one per overlapping splat); off:
    /// the nearest of the MLS hits of every ellipse hit.
    pub nearest_ellipse: bool,
    /// Reject an ellipse hit without the MLS iteration when its surfel's whole leaf ball is
    /// clipped (§4.3; `DeformTracer::ball_clipped`, not in the paper). Same hits; off:
    /// every ellipse hit of a clipped surface is iterated and then clipped, as in the paper.
    pub clip_early: bool,
    /// Per-ray cache (LazyCache) under front-to-back traversal (`ordered`): the cache is
    /// looked up only while at least this share of its lookups hit (checked every frame it
    /// runs, and on a probe every [`CACHE_PROBE`] frames while it rests) and its lookups
    /// save 5 % of the sphere and leaf tests against an adjacent frame without them
    /// (checked every [`CACHE_PROBE`] frames); 0 = every frame, as in the paper. Not in the
    /// paper: front-to-back descent finds the near hit that a cached node would bound the
    /// ray with by itself, so a cache that misses, or hits without saving tests, is pure
    /// cost (module docs, "Cache gate"). The unordered descent always runs it.
    pub cache_gate: f32,
}

/// Upper limit of [`TraceParams::exact_below`] (2²⁴ surfels: any subtree of the built-in
/// models; one thread refits a subtree, so a whole large tree would serialise the frame).
pub const MAX_EXACT_BELOW: u32 = 1 << 24;

/// Subtrees of more surfels than this are refitted by one thread per frame
/// (`DeformTracer::refit_subtree`); smaller ones cost less to redo than to coordinate.
const REFIT_CLAIM_MIN: u32 = 64;

/// A refitted node of at most this many surfels takes the smallest sphere around its two
/// children's (Eq. 11 re-centred) instead of the exact reach from its box centre
/// (`DeformTracer::refit_subtree`). Around two leaf balls that sphere is the smallest; for
/// three it is as tight in the sum (sphere tests within 0.2 % on `elastic-balls` and
/// `armadillo-ball`, stop 71) and saves a reach step of eight lanes for three balls at
/// about a third of the nodes: whole-ball refits 3 % faster. With 7 the chain of square
/// roots and divisions up the tree took that back.
const ENC_MAX: usize = 3;

/// Per-thread buffers of `DeformTracer::refit_subtree`: the subtree's leaf balls in leaf
/// order (SoA, for [`max_reach_x8`]) and each node's bounding box of leaf-ball centres
/// (16-byte `Vec3A`: a parent reads its children's boxes right after they were written, and
/// a 12-byte `Vec3` store does not forward to the vector load: `elastic-balls`' whole-ball
/// refits 18.3 → 17.6 ms/frame on one thread, stop 70).
#[derive(Default)]
struct RefitScratch {
    x: Vec<f32>,
    y: Vec<f32>,
    z: Vec<f32>,
    r: Vec<f32>,
    lo: Vec<Vec3A>,
    hi: Vec<Vec3A>,
    sph: Vec<(Vec3, f32)>,
}

/// Per-thread buffers of the packet traversals (`intersect_x8`, `occluded_x8`): the
/// instances a packet reaches and the traversal stacks, kept across packets so that a packet
/// allocates nothing (taken out while in use; a nested use would just allocate).
#[derive(Default)]
struct PacketScratch {
    roots: Vec<(f32, usize, u8, f32x8)>,
    stack: Vec<(u32, u32, u8, u8, f32x8)>,
    any: Vec<(u32, u32, u8, u8)>,
}

thread_local! {
    static PACKET_SCRATCH: std::cell::Cell<PacketScratch> = std::cell::Cell::new(PacketScratch::default());
}

/// Takes this thread's [`PacketScratch`] (its vectors cleared) for one packet.
fn take_scratch() -> PacketScratch {
    let mut sc = PACKET_SCRATCH.take();
    sc.roots.clear();
    sc.stack.clear();
    sc.any.clear();
    sc
}

thread_local! {
    static REFIT_SCRATCH: std::cell::RefCell<RefitScratch> = std::cell::RefCell::new(RefitScratch::default());
}

/// How many slots ahead of a packet's [`DeformTracer::prefetch_cached`] requests the
/// cache's line: 32 pixels, eight 4×2 packets along a row.
const CACHE_AHEAD: usize = 32;

/// While the per-ray cache rests ([`TraceParams::cache_gate`]), every this many frames one
/// looks it up again (the frame before it refreshes the slots).
pub const CACHE_PROBE: u32 = 8;

/// A frame's lookups decide the cache gate only if there are at least this many (a few rays
/// on the object say nothing about the cache; the gate then stays as it was).
const CACHE_GATE_MIN_LOOKUPS: u64 = 256;

/// The share of a frame's sphere and leaf tests that its cache lookups must save, against
/// an adjacent frame without them, for the gate to keep or open the cache
/// ([`TraceParams::cache_gate`]).
const CACHE_GATE_SAVING: f64 = 0.05;

/// Upper limit of [`TraceParams::cache_up`] (deeper than any tree: the root is cached).
pub const MAX_CACHE_UP: u32 = 64;

impl Default for TraceParams {
    fn default() -> Self {
        TraceParams {
            mls: MlsParams::default(),
            factor_rigid: true,
            eq11: true,
            shadow_updated_first: true,
            max_support_stretch: 3.0,
            cache_up: 0,
            cache_climb: false,
            ordered: true,
            recentred_bound: true,
            node_rotation: true,
            exact_below: 4096,
            recentre_eq11: true,
            instance_tree: true,
            nearest_ellipse: true,
            clip_early: true,
            cache_gate: 0.25,
        }
    }
}

/// The deformable objects of a scene: shared precomputed models and the instances (one per
/// simulated body; `instances[b]` is the object of body b).
#[derive(Clone, Debug)]
pub struct DeformScene {
    pub objects: Vec<Arc<SurfelObject>>,
    pub instances: Vec<u32>,
}

/// A closest (or any) hit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfelHit {
    /// Ray parameter (in multiples of the ray direction).
    pub t: f32,
    pub p: Vec3,
    /// MLS normal n(x), unit, pointing out of the surface.
    pub n: Vec3,
    pub instance: u32,
    /// Surfel whose leaf produced the hit, and its collection.
    pub surfel: u32,
    pub collection: u32,
    /// Leaf node of the hit (in the lazy hierarchy; naive trees are rebuilt every frame).
    pub node: u32,
    /// MLS evaluations until convergence.
    pub iterations: u32,
    /// Ray parameter of the ellipse hit that started the MLS iteration: with
    /// `TraceParams::nearest_ellipse` the order of closest hits, except for surfels of
    /// clipped collections, which `t` orders (as it orders every hit under the paper's rule).
    pub t0: f32,
}

/// Per-thread work counters of the deform tracer (merge by addition).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct DeformCounters {
    /// Ray–sphere tests (roots, inner nodes, leaves, the cached node).
    pub sphere_tests: u64,
    /// Leaves reached: ellipse tests.
    pub leaf_tests: u64,
    /// MLS iterations started (ellipse hit).
    pub mls_runs: u64,
    pub mls_iterations: u64,
    pub mls_hits: u64,
    pub mls_rejected: u64,
    /// Accepted MLS hits rejected by clipping.
    pub clipped: u64,
    /// Ellipse hits whose whole leaf ball is clipped (§4.3), rejected without the MLS
    /// iteration (`DeformTracer::ball_clipped`); not in `mls_runs`.
    pub clipped_early: u64,
    pub cache_lookups: u64,
    /// The cached node gave a hit (under the nearest-ellipse rule: the first pass's candidate,
    /// which may still be rejected).
    pub cache_hits: u64,
    /// Shadow rays (`occluded*`, valid ones): asked, those whose segment entered some
    /// object's root sphere (sphere-tree modes; 0 under `refit`), those occluded, and the
    /// sphere and leaf tests they took (a part of `sphere_tests` + `leaf_tests`). Where the
    /// any-hit rays' work goes: on `bend` packets in which no ray is occluded take 59 % of
    /// it, which no cache of an occluder can shorten (BENCHMARKS.md, "Stop 87").
    pub shadow_rays: u64,
    pub shadow_entered: u64,
    pub shadow_occluded: u64,
    pub shadow_tests: u64,
    /// `sphere_tests` inside the objects' sphere trees by the tested node's level (0: the
    /// roots; deeper than [`LEVELS`] − 1 counts in the last). The instance tree's tests and
    /// the `refit` mode's box tests are not included, so in a scene of one object the levels
    /// sum to `sphere_tests`. Shows where one hierarchy tests more than another (README,
    /// "Whole sequences").
    pub level_tests: [u64; LEVELS],
}

/// Levels of [`DeformCounters::level_tests`].
pub const LEVELS: usize = 32;

/// Flag of a packet traversal's stack entry (in its level byte, below the shadow
/// traversal's `UNTESTED`): the node's subtree is known to be complete
/// (`DeformTracer::compact_children`).
const COMPLETE: u8 = 0x40;

impl DeformCounters {
    pub fn merge(&mut self, o: &DeformCounters) {
        self.sphere_tests += o.sphere_tests;
        self.leaf_tests += o.leaf_tests;
        self.mls_runs += o.mls_runs;
        self.mls_iterations += o.mls_iterations;
        self.mls_hits += o.mls_hits;
        self.mls_rejected += o.mls_rejected;
        self.clipped += o.clipped;
        self.clipped_early += o.clipped_early;
        self.cache_lookups += o.cache_lookups;
        self.cache_hits += o.cache_hits;
        self.shadow_rays += o.shadow_rays;
        self.shadow_entered += o.shadow_entered;
        self.shadow_occluded += o.shadow_occluded;
        self.shadow_tests += o.shadow_tests;
        for (a, b) in self.level_tests.iter_mut().zip(&o.level_tests) {
            *a += b;
        }
    }
    /// Counts `n` sphere tests of nodes at `level`.
    #[inline(always)]
    fn tests_at(&mut self, level: u8, n: u64) {
        self.level_tests[(level as usize).min(LEVELS - 1)] += n;
    }
    /// [`tests_at`](Self::tests_at) of a level the caller clamped below [`LEVELS`] already
    /// (the packet traversals, whose stacks carry clamped levels).
    #[inline(always)]
    fn tests_below(&mut self, level: u8, n: u64) {
        const { assert!(LEVELS.is_power_of_two() && LEVELS <= COMPLETE as usize) };
        debug_assert!((level as usize) < LEVELS);
        self.level_tests[level as usize & (LEVELS - 1)] += n;
    }
    /// Mean MLS iterations of converged hits and rejections together.
    pub fn mean_mls_iterations(&self) -> f64 {
        self.mls_iterations as f64 / (self.mls_runs.max(1)) as f64
    }
}

/// Per-frame update statistics (read after the frame's rays).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameStats {
    pub frame: u32,
    pub mode: String,
    /// Wall time of `begin_frame` (field, and for naive the deformation and rebuild).
    pub update_seconds: f64,
    pub inner_nodes_total: u64,
    /// Inner nodes whose centre and radius were computed this frame (naive: all, rebuilt).
    pub inner_nodes_updated: u64,
    /// Inner nodes whose radius Eq. 11 reduced below the Eq. 9 bound.
    pub nodes_tightened: u64,
    pub surfels_total: u64,
    pub surfels_deformed: u64,
}

/// Radius tightness at one level: used radius / tightest radius (miniball of the deformed
/// surfel centres, grown by their ellipse extents — the construction of the initial tree).
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct LevelRatio {
    pub level: u32,
    pub nodes_updated: u64,
    pub sampled: u64,
    pub mean_ratio: f64,
    pub max_ratio: f64,
}

/// One surfel's lazily deformed state in one 64-byte line: the frame stamp, then p, u, v,
/// stretch, the unit normal u×v and the leaf-ball radius (stored at deformation time so that
/// the 16-surfel MLS neighbourhoods and the small-node spheres do not recompute them). A leaf
/// test reads 17 surfels at random places: one line each, where separate stamp and data
/// arrays (40 bytes, straddling lines) cost two or three (measured: `armadillo-ball` −8 % per
/// frame).
#[repr(C, align(64))]
struct SurfSlot {
    stamp: AtomicU32,
    d: [AtomicU32; SURF_F],
}

const SURF_F: usize = 14;
const _: () = assert!(std::mem::size_of::<SurfSlot>() == 64);

struct SurfelState {
    slot: Vec<SurfSlot>,
}

impl SurfelState {
    fn new(n: usize) -> Self {
        SurfelState { slot: (0..n).map(|_| SurfSlot { stamp: AtomicU32::new(0), d: std::array::from_fn(|_| AtomicU32::new(0)) }).collect() }
    }
}

/// The lazily written state of one node: frame stamps, centre and radius. One 32-byte
/// record per node (not split per field like the static tree): a scalar traversal reads all
/// of it at once, so a record costs one cache line where five arrays would cost five, and
/// writes from one thread invalidate one line. (Measured on `armadillo-ball`, detail 0.2:
/// see the report in `mod.rs`.)
///
/// **Publication protocol.** Within a frame a node's sphere is written once (its first
/// computation) and then only replaced by a smaller one (Eq. 11), possibly with a moved
/// centre. The centre and radius are four separate words, so they are published under a
/// sequence lock: `seq` is odd while a writer holds it (a try-lock: a writer that finds it
/// taken skips its write, which is always allowed), and a reader retries until it read all
/// four words between two equal, even values of `seq`. Every sphere a reader assembles is
/// therefore one that a writer published, and each of those bounds the node.
///
/// (Until stop 31 readers took the radius with acquire and then the centre's three words,
/// on the argument that a later centre with an earlier, larger radius still bounds the
/// node. A review found the flaw: the three words could come from different writes, and
/// such a mixed centre lies in neither sphere — 1,700–5,400 of 77–186 k centre moves per
/// sequence at detail 0.1 would have left a surfel up to 5.7 % of r outside.)
#[repr(C, align(32))]
struct NodeSlot {
    stamp: AtomicU32,
    tight: AtomicU32,
    c: [AtomicU32; 3],
    r: AtomicU32,
    seq: AtomicU32,
    /// `frame << 1` when a thread has taken on this frame's subtree refit of this node
    /// (`DeformTracer::refit_subtree`), `frame << 1 | 1` once the refit has written every
    /// [`Ball`] of the subtree ("complete", `DeformTracer::compact_children`). Frames are
    /// counted in 31 bits here: after 2³¹ frames a stale value could read as this frame's.
    claim: AtomicU32,
}

const _: () = assert!(std::mem::size_of::<NodeSlot>() == 32);

impl NodeSlot {
    /// Takes on this frame's refit of the node's subtree, unless a thread already has.
    #[inline]
    fn try_claim(&self, frame: u32) -> bool {
        let mine = frame << 1;
        let mut old = self.claim.load(Relaxed);
        loop {
            if old >> 1 == mine >> 1 {
                return false;
            }
            match self.claim.compare_exchange_weak(old, mine, AcqRel, Relaxed) {
                Ok(_) => return true,
                Err(v) => old = v,
            }
        }
    }
    /// After every ball of the subtree has been written this frame (release: a reader that
    /// sees it with [`Self::complete`] sees the balls).
    #[inline(always)]
    fn mark_complete(&self, frame: u32) {
        self.claim.store(frame << 1 | 1, Release);
    }
    #[inline(always)]
    fn complete(&self, frame: u32) -> bool {
        self.claim.load(Acquire) == frame << 1 | 1
    }
    #[inline(always)]
    fn try_lock(&self) -> bool {
        let v = self.seq.load(Relaxed);
        if v & 1 != 0 || self.seq.compare_exchange(v, v.wrapping_add(1), Acquire, Relaxed).is_err() {
            return false;
        }
        // The odd value is ordered before the data stores that follow (a seqlock writer).
        std::sync::atomic::fence(Release);
        true
    }
    #[inline(always)]
    fn unlock(&self) {
        let v = self.seq.load(Relaxed);
        self.seq.store(v.wrapping_add(1), Release);
    }
    /// Between [`Self::try_lock`] and [`Self::unlock`], which publish it, or as
    /// [`NodeState::publish`] allows without them.
    #[inline(always)]
    fn write(&self, c: Vec3, r: f32) {
        self.c[0].store(c.x.to_bits(), Relaxed);
        self.c[1].store(c.y.to_bits(), Relaxed);
        self.c[2].store(c.z.to_bits(), Relaxed);
        self.r.store(r.to_bits(), Relaxed);
    }
}

struct NodeState {
    slot: Vec<NodeSlot>,
}

impl NodeState {
    fn new(n: usize) -> Self {
        NodeState {
            slot: (0..n)
                .map(|_| NodeSlot {
                    stamp: AtomicU32::new(0),
                    tight: AtomicU32::new(0),
                    c: [AtomicU32::new(0), AtomicU32::new(0), AtomicU32::new(0)],
                    r: AtomicU32::new(0),
                    seq: AtomicU32::new(0),
                    claim: AtomicU32::new(0),
                })
                .collect(),
        }
    }
    /// The node's current sphere (after its stamp was seen with acquire).
    #[inline(always)]
    fn load(&self, n: usize) -> (Vec3, f32) {
        let s = &self.slot[n];
        let g = |a: &AtomicU32| f32::from_bits(a.load(Relaxed));
        loop {
            let v = s.seq.load(Acquire);
            let (c, r) = (Vec3::new(g(&s.c[0]), g(&s.c[1]), g(&s.c[2])), g(&s.r));
            std::sync::atomic::fence(Acquire);
            if v & 1 == 0 && s.seq.load(Relaxed) == v {
                return (c, r);
            }
            std::hint::spin_loop();
        }
    }
    /// [`store`](Self::store), or with `plain` stores outside the lock: for a slot that no
    /// other thread reads or writes until the caller's task has ended (the stamp's release
    /// store and the join of the task publish them), or one that every writer writes with the
    /// same values (`DeformTracer::refit_subtree`).
    #[inline(always)]
    fn publish(&self, n: usize, c: Vec3, r: f32, frame: u32, plain: bool) {
        if plain {
            let s = &self.slot[n];
            s.write(c, r);
            s.stamp.store(frame, Release);
        } else {
            self.store(n, c, r, frame);
        }
    }

    /// First computation of the node in `frame`: published unless another thread already
    /// did (or holds the lock; the caller uses its own values either way).
    #[inline(always)]
    fn store(&self, n: usize, c: Vec3, r: f32, frame: u32) {
        let s = &self.slot[n];
        if s.try_lock() {
            if s.stamp.load(Relaxed) != frame {
                s.write(c, r);
                s.stamp.store(frame, Release);
            }
            s.unlock();
        }
    }
}

/// A node's sphere as this frame's subtree refit computed it ([`DeformTracer::refit_subtree`]),
/// for every node of the static tree, leaves included, in its pre-order: the compact copy
/// that traversals read below [`DeformTracer::compact_max`] (module docs, "Compact balls").
#[repr(C, align(16))]
struct Ball([AtomicU32; 4]);

impl Ball {
    #[inline(always)]
    fn load(&self) -> (Vec3, f32) {
        let g = |i: usize| f32::from_bits(self.0[i].load(Relaxed));
        (Vec3::new(g(0), g(1), g(2)), g(3))
    }
    #[inline(always)]
    fn store(&self, (c, r): (Vec3, f32)) {
        for (a, x) in self.0.iter().zip([c.x, c.y, c.z, r]) {
            a.store(x.to_bits(), Relaxed);
        }
    }
}

struct Instance {
    obj: Arc<SurfelObject>,
    field: DeformField,
    surf: SurfelState,
    nodes: NodeState,
    /// [`Ball`]s of the static tree's nodes (written only by subtree refits).
    ball: Vec<Ball>,
    naive: Option<Topology>,
    refit: Option<Bvh2>,
    /// Some collection of the object has clipping partners (§4.3).
    clipped: bool,
}

/// The order of a closest-hit search (module docs, "Nearest ellipse").
#[derive(Clone, Copy, PartialEq, Eq, Debug)]
enum Rule {
    /// The paper's: every ellipse hit is iterated and the nearest MLS hit kept (key: `t`).
    EveryMls,
    /// Nearest ellipse, deferred: a pass only finds the nearest ellipse hit above `floor`
    /// (`Best::cand`), which is iterated after the pass (key: `t0`).
    Deferred,
    /// Nearest ellipse after [`MAX_DEFERRED_PASSES`] rejected candidates: every ellipse hit
    /// above `floor` that beats the best is iterated at once. Same answer, one more pass.
    AboveFloor,
}

/// Passes of [`Rule::Deferred`] before a ray switches to [`Rule::AboveFloor`].
const MAX_DEFERRED_PASSES: u32 = 1;

/// An ellipse hit not yet iterated: ray parameter, instance, surfel, leaf node.
#[derive(Clone, Copy)]
struct Cand {
    t0: f32,
    k: u32,
    s: u32,
    node: u32,
}

/// A ray's closest-hit search. `t` bounds the traversal: the ray's `tfar` until a hit or
/// candidate is found, then its order key (the MLS `t` under [`Rule::EveryMls`], else the
/// ellipse hit's `t0`). Both lie inside the leaf ball, so a node whose ball the ray enters
/// beyond `t` holds no better hit. Ties go to the smaller (instance, surfel).
#[derive(Clone, Copy)]
struct Best {
    t: f32,
    hit: Option<SurfelHit>,
    cand: Option<Cand>,
    /// Ellipse hits up to this (key, instance, surfel) were iterated and rejected.
    floor: (f32, u32, u32),
    rule: Rule,
    tfar: f32,
    passes: u32,
}

impl Best {
    #[inline]
    fn new(tfar: f32, nearest_ellipse: bool) -> Self {
        let rule = if nearest_ellipse { Rule::Deferred } else { Rule::EveryMls };
        Best { t: tfar, hit: None, cand: None, floor: (f32::NEG_INFINITY, 0, 0), rule, tfar, passes: 0 }
    }
    /// Whether an ellipse or MLS hit of (instance `k`, surfel `s`) with order key `key`
    /// would beat the best hit or candidate.
    #[inline]
    fn beaten_by(&self, key: f32, k: u32, s: u32) -> bool {
        let id = match (self.cand, self.hit) {
            (Some(c), _) => (c.k, c.s),
            (None, Some(h)) => (h.instance, h.surfel),
            (None, None) => return key <= self.t,
        };
        key < self.t || (key == self.t && (k, s) < id)
    }
    /// Above the rejected candidates?
    #[inline]
    fn above_floor(&self, key: f32, k: u32, s: u32) -> bool {
        let f = self.floor;
        key > f.0 || (key == f.0 && (k, s) > (f.1, f.2))
    }
    /// An accepted hit with order key `key`.
    #[inline]
    fn offer(&mut self, h: SurfelHit, key: f32) {
        if self.above_floor(key, h.instance, h.surfel) && self.beaten_by(key, h.instance, h.surfel) {
            self.t = key;
            self.hit = Some(h);
            self.cand = None;
        }
    }
    /// An ellipse hit to iterate after the pass ([`Rule::Deferred`]).
    #[inline]
    fn propose(&mut self, c: Cand) {
        if self.above_floor(c.t0, c.k, c.s) && self.beaten_by(c.t0, c.k, c.s) {
            self.t = c.t0;
            self.cand = Some(c);
            self.hit = None;
        }
    }
    /// Something found (a hit, or a candidate still to iterate)?
    #[inline]
    fn found(&self) -> bool {
        self.hit.is_some() || self.cand.is_some()
    }
}

const NO_CACHE: u64 = u64::MAX;

/// The per-frame tracer of deforming surfel objects (see module docs).
pub struct DeformTracer {
    mode: UpdateMode,
    params: TraceParams,
    inst: Vec<Instance>,
    frame: u32,
    cache: Vec<AtomicU64>,
    update_seconds: f64,
    /// The instances' sphere tree of this frame ([`super::top`]).
    top: TopTree,
    /// `UpdateMode::Auto`'s state.
    auto: AutoPick,
    /// The per-ray cache's gate ([`TraceParams::cache_gate`]): on while its lookups hit
    /// often enough and save work; `look` and `keep`: this frame looks the slots up, stores
    /// into them; `gate_prev`: the last reported frame's sphere and leaf tests, whether it
    /// looked up, and its lookups (for the probes' comparison).
    cache_on: bool,
    cache_look: bool,
    cache_keep: bool,
    gate_prev: Option<(u64, bool, u64)>,
}

impl DeformTracer {
    pub fn new(scene: &DeformScene, mode: UpdateMode, params: TraceParams) -> Result<Self, DeformError> {
        if scene.instances.is_empty() {
            return Err(DeformError::Invalid("scene has no instances".into()));
        }
        let p = &params;
        if !(p.mls.eps_rel.is_finite() && p.mls.eps_rel > 0.0) || p.mls.max_iter == 0 || !(p.max_support_stretch >= 1.0) {
            return Err(DeformError::Invalid(format!("bad trace parameters {p:?}")));
        }
        let mut inst = Vec::with_capacity(scene.instances.len());
        for &o in &scene.instances {
            let obj = scene.objects.get(o as usize).ok_or_else(|| DeformError::Invalid(format!("instance of missing object {o}")))?.clone();
            let (ns, nn) = (obj.surfel_count(), obj.tree.len());
            inst.push(Instance {
                field: DeformField::identity(&obj.nodes),
                surf: SurfelState::new(ns),
                nodes: NodeState::new(nn),
                ball: (0..nn).map(|_| Ball(std::array::from_fn(|_| AtomicU32::new(0)))).collect(),
                naive: None,
                refit: (mode == UpdateMode::Refit).then(|| refit_build(&obj)),
                clipped: obj.clip_partners.iter().any(|p| !p.is_empty()),
                obj,
            });
        }
        Ok(DeformTracer {
            mode,
            params,
            inst,
            frame: 0,
            cache: Vec::new(),
            update_seconds: 0.0,
            top: TopTree::default(),
            auto: AutoPick::default(),
            cache_on: true,
            cache_look: mode == UpdateMode::LazyCache,
            cache_keep: mode == UpdateMode::LazyCache,
            gate_prev: None,
        })
    }

    pub fn mode(&self) -> UpdateMode {
        self.mode
    }
    pub fn params(&self) -> &TraceParams {
        &self.params
    }
    pub fn frame(&self) -> u32 {
        self.frame
    }
    pub fn instance_count(&self) -> usize {
        self.inst.len()
    }
    pub fn object(&self, instance: usize) -> &Arc<SurfelObject> {
        &self.inst[instance].obj
    }

    /// Reports the frame begun last: its wall time (its `begin_frame` and its rays), which
    /// `UpdateMode::Auto` compares between its two modes, and its counters, whose cache
    /// lookups and hits set the cache gate ([`TraceParams::cache_gate`]). A caller that never
    /// reports leaves the cache on every frame.
    pub fn end_frame(&mut self, seconds: f64, dc: &DeformCounters) {
        if self.mode == UpdateMode::Auto {
            self.auto.record(seconds);
        }
        if self.cache_gated() {
            let work = dc.sphere_tests + dc.leaf_tests;
            // Lookups pay when a frame with them takes CACHE_GATE_SAVING fewer tests than
            // the frame before or after without them (the probes; adjacent frames differ by
            // a frame's motion, 1–2 % of the tests on the built-in sequences).
            let saves = |with: u64, without: u64| (with as f64) < (1.0 - CACHE_GATE_SAVING) * without as f64;
            let enough = dc.cache_lookups >= CACHE_GATE_MIN_LOOKUPS;
            let hit = dc.cache_hits as f64 >= self.params.cache_gate as f64 * dc.cache_lookups as f64;
            match (self.cache_on, self.cache_look, self.gate_prev) {
                // Open: a frame whose lookups miss too often closes it.
                (true, true, _) if enough => self.cache_on = hit,
                // Open, a frame without lookups after one with them: it stays open only if
                // the lookups saved tests.
                (true, false, Some((w, true, l))) if l >= CACHE_GATE_MIN_LOOKUPS => self.cache_on = saves(w, work),
                // Closed, a probe after a frame without lookups: it opens if the lookups hit
                // often enough and saved tests.
                (false, true, Some((w, false, _))) if enough => self.cache_on = hit && saves(work, w),
                _ => {}
            }
            self.gate_prev = Some((work, self.cache_look, dc.cache_lookups));
        }
    }

    /// Whether the per-ray cache is gated ([`TraceParams::cache_gate`]).
    fn cache_gated(&self) -> bool {
        self.mode == UpdateMode::LazyCache && self.params.ordered && self.params.cache_gate > 0.0
    }

    /// Sizes the per-ray cache (LazyCache): slots `0..n` (e.g. one per pixel). Clears it.
    pub fn set_cache_slots(&mut self, n: usize) {
        self.cache = (0..n).map(|_| AtomicU64::new(NO_CACHE)).collect();
    }

    /// Starts a frame: `nodes[b]` are the deformed simulation-node positions of body b.
    pub fn begin_frame(&mut self, nodes: &[Vec<Vec3>]) -> Result<(), DeformError> {
        if nodes.len() != self.inst.len() {
            return Err(DeformError::FrameMismatch(format!("{} bodies in the frame, {} instances", nodes.len(), self.inst.len())));
        }
        let t0 = Instant::now();
        let fields: Vec<DeformField> = self
            .inst
            .par_iter()
            .zip(nodes.par_iter())
            .map(|(i, x)| DeformField::compute(&i.obj.nodes, x, self.params.factor_rigid))
            .collect::<Result<_, _>>()?;
        self.frame = self.frame.wrapping_add(1).max(1);
        let frame = self.frame;
        if self.mode == UpdateMode::LazyCache {
            // A resting cache is probed every CACHE_PROBE frames, with the slots its
            // previous frame stored.
            // An open one skips its lookups every CACHE_PROBE frames (once frames are
            // reported), keeping its slots, to measure what they save.
            let (gated, probe) = (self.cache_gated(), frame.is_multiple_of(CACHE_PROBE));
            let on = self.cache_on || !gated;
            self.cache_look = if on { !(gated && probe && self.gate_prev.is_some()) } else { probe };
            self.cache_keep = on || probe || frame.wrapping_add(1).is_multiple_of(CACHE_PROBE);
        }
        for (i, f) in self.inst.iter_mut().zip(fields) {
            i.field = f;
        }
        let naive = match self.mode {
            UpdateMode::Naive => true,
            UpdateMode::Auto => self.auto.pick(),
            _ => false,
        };
        if naive {
            for i in self.inst.iter_mut() {
                let obj = &i.obj;
                let def: Vec<DeformedSurfel> = (0..obj.surfel_count()).into_par_iter().map(|s| deform_surfel(obj, &i.field, s)).collect();
                let mut ext = vec![0.0f32; def.len()];
                def.par_chunks(8).zip(ext.par_chunks_mut(8)).enumerate().for_each(|(ci, (d8, e8))| {
                    let (nrm, e) = normal_extent_x8(d8);
                    for (j, d) in d8.iter().enumerate() {
                        store_surfel_nr(&i.surf, ci * 8 + j, d, nrm[j], e[j] * (1.0 + RADIUS_PAD), frame);
                        e8[j] = e[j];
                    }
                });
                let pts: Vec<Vec3> = def.iter().map(|d| d.p).collect();
                i.naive = Some(Topology::build(&pts, &ext));
            }
        } else if self.mode == UpdateMode::Refit {
            for i in self.inst.iter_mut() {
                let (obj, field, surf) = (&i.obj, &i.field, &i.surf);
                (0..obj.surfel_count()).into_par_iter().for_each(|s| {
                    store_surfel(surf, s, &deform_surfel(obj, field, s), frame);
                });
                let bvh = i.refit.as_mut().expect("refit tree");
                let prims = &bvh.primitive_indices;
                bvh.nodes.par_iter_mut().filter(|n| n.is_leaf()).for_each(|n| {
                    let mut b = Aabb::empty();
                    for &s in &prims[n.first_index as usize..(n.first_index + n.prim_count) as usize] {
                        b = b.union(&ball_box(&load_surfel(surf, s as usize)));
                    }
                    n.set_aabb(b);
                });
                bvh.refit_all();
            }
        } else {
            for i in self.inst.iter_mut() {
                i.naive = None;
            }
        }
        // The instance tree over this frame's root spheres (in the lazy modes this makes the
        // roots current, which every ray used to do by testing all of them).
        let roots: Vec<(Vec3, f32)> = self
            .inst
            .par_iter()
            .map(|ii| match &ii.refit {
                Some(bvh) => bvh.nodes.first().map_or((Vec3::ZERO, -1.0), |n| {
                    let b = n.aabb();
                    let (lo, hi) = (Vec3::from(b.min), Vec3::from(b.max));
                    let c = 0.5 * (lo + hi);
                    let r = 0.5 * (hi - lo).length();
                    (c, r * (1.0 + RADIUS_PAD) + RADIUS_PAD * c.abs().max_element())
                }),
                None => self.root_before_rays(ii),
            })
            .collect();
        self.top = if self.params.instance_tree { TopTree::build(&roots) } else { TopTree::flat(roots.len()) };
        self.update_seconds = t0.elapsed().as_secs_f64();
        Ok(())
    }

    /// [`sphere`](Self::sphere) of instance `ii`'s root in `begin_frame`: no ray runs yet and
    /// each instance is one task, so a refit of the root publishes without locks.
    fn root_before_rays(&self, ii: &Instance) -> (Vec3, f32) {
        if ii.naive.is_some() || ii.obj.tree.topo.right[0] == LEAF || self.current(ii, 0) {
            return self.sphere(ii, 0);
        }
        self.update_sphere_with(ii, 0, true)
    }

    // -- lazy state ------------------------------------------------------------------------

    /// Surfel `s` in this frame, read with `load` if another ray already deformed it in this
    /// frame, else deformed (Eq. 1), stored, and passed to `fresh`.
    #[inline(always)]
    fn surfel_as<T>(&self, ii: &Instance, s: usize, load: fn(&SurfelState, usize) -> T, fresh: fn(&DeformedSurfel, Vec3, f32) -> T) -> T {
        if ii.surf.slot[s].stamp.load(Acquire) == self.frame {
            load(&ii.surf, s)
        } else {
            let (d, n, r) = self.deform_store(ii, s);
            fresh(&d, n, r)
        }
    }

    /// The lazy path of [`surfel_as`](Self::surfel_as): surfel `s` deformed (Eq. 1) and
    /// stored, with its normal and leaf radius. Out of line: the MLS neighbourhood gathers
    /// sixteen surfels through `surfel_as`, nearly all of them current, and this body
    /// inlined into each gather step cost more than the call does when it is needed.
    #[cold]
    #[inline(never)]
    fn deform_store(&self, ii: &Instance, s: usize) -> (DeformedSurfel, Vec3, f32) {
        let d = deform_surfel(&ii.obj, &ii.field, s);
        let (n, r) = store_surfel(&ii.surf, s, &d, self.frame);
        (d, n, r)
    }

    #[inline]
    fn surfel(&self, ii: &Instance, s: usize) -> DeformedSurfel {
        self.surfel_as(ii, s, load_surfel, |d, _, _| *d)
    }

    /// The leaf ball of surfel `s` in this frame ([`leaf_sphere`], stored with the surfel).
    #[inline]
    fn surfel_ball(&self, ii: &Instance, s: usize) -> (Vec3, f32) {
        self.surfel_as(ii, s, load_surfel_ball, |d, _, r| (d.p, r))
    }

    /// Position and unit normal of surfel `s` in this frame (deforming it lazily).
    #[inline]
    fn surfel_pn(&self, ii: &Instance, s: usize) -> (Vec3, Vec3) {
        self.surfel_as(ii, s, load_surfel_pn, |d, n, _| (d.p, n))
    }

    #[inline]
    fn topo<'a>(&self, ii: &'a Instance) -> &'a Topology {
        ii.naive.as_ref().unwrap_or(&ii.obj.tree.topo)
    }

    /// Whether node n's sphere is this frame's. A leaf's sphere is its surfel's ball, kept in
    /// the surfel's slot (see [`Self::sphere`]).
    #[inline]
    fn current(&self, ii: &Instance, n: usize) -> bool {
        if ii.naive.is_some() {
            return true;
        }
        match leaf_surfel(ii, n) {
            Some(s) => ii.surf.slot[s].stamp.load(Relaxed) == self.frame,
            None => ii.nodes.slot[n].stamp.load(Relaxed) == self.frame,
        }
    }

    /// The sphere of node n in this frame (updating it lazily: Eq. 3–4, 9 for inner nodes,
    /// the deformed surfel (Eq. 1) for leaves).
    #[inline(always)]
    fn sphere(&self, ii: &Instance, n: usize) -> (Vec3, f32) {
        if let Some(t) = &ii.naive {
            return (t.center(n), t.r[n]);
        }
        self.sphere_as(ii, n, ii.obj.tree.topo.right[n] == LEAF)
    }

    /// [`sphere`](Self::sphere) of a node whose leafness the caller knows
    /// (a count of 1, [`Topology::split`]): the node's slot (or its surfel's) is loaded without
    /// waiting for the load of its `right` first, a second cache miss in a row for a far
    /// right child.
    #[inline(always)]
    fn sphere_as(&self, ii: &Instance, n: usize, leaf: bool) -> (Vec3, f32) {
        self.sphere_as_nv(ii, ii.naive.as_ref(), n, leaf)
    }

    /// [`sphere_as`](Self::sphere_as) with `ii.naive` read by the caller (`nv`), once per
    /// traversal of the instance rather than per node.
    #[inline(always)]
    fn sphere_as_nv(&self, ii: &Instance, nv: Option<&Topology>, n: usize, leaf: bool) -> (Vec3, f32) {
        if let Some(t) = nv {
            return (t.center(n), t.r[n]);
        }
        // A leaf's sphere is its surfel's leaf ball, stored with the deformed surfel (§4.1.2
        // updates leaves from their surfel), not in the node's slot: the refit of a subtree
        // then publishes only its inner nodes, half of them, and a leaf whose test passes
        // finds its surfel's line, which the ellipse test reads next, already loaded.
        if leaf {
            return self.surfel_ball(ii, ii.obj.tree.topo.surfel[n] as usize);
        }
        let st = &ii.nodes;
        if st.slot[n].stamp.load(Acquire) == self.frame {
            return st.load(n);
        }
        self.update_sphere(ii, n)
    }

    /// Node n's sphere if it is current in this frame (always in the naive tree), else None
    /// (nothing is updated): [`current`](Self::current) and [`sphere`](Self::sphere) in one
    /// stamp check. The caller knows whether n is a leaf ([`Topology::split`]).
    #[inline(always)]
    fn current_sphere(&self, ii: &Instance, nv: Option<&Topology>, n: usize, leaf: bool) -> Option<(Vec3, f32)> {
        if let Some(t) = nv {
            return Some((t.center(n), t.r[n]));
        }
        if leaf {
            let s = ii.obj.tree.topo.surfel[n] as usize;
            return (ii.surf.slot[s].stamp.load(Acquire) == self.frame).then(|| load_surfel_ball(&ii.surf, s));
        }
        (ii.nodes.slot[n].stamp.load(Acquire) == self.frame).then(|| ii.nodes.load(n))
    }

    /// The first computation of inner node n's sphere in this frame (out of line: the common path
    /// of [`Self::sphere`] is a stamp check and a load, and inlining this body's large stack
    /// frame into every caller costs more than the call).
    #[inline(never)]
    fn update_sphere(&self, ii: &Instance, n: usize) -> (Vec3, f32) {
        self.update_sphere_with(ii, n, false)
    }

    /// [`update_sphere`](Self::update_sphere); `exclusive`: no other thread reads or writes
    /// this instance's slots meanwhile (`begin_frame`'s roots, before any ray), so a refit
    /// publishes its nodes with plain stores instead of each under the node's sequence lock.
    #[inline(always)]
    fn update_sphere_with(&self, ii: &Instance, n: usize, exclusive: bool) -> (Vec3, f32) {
        let tree = &ii.obj.tree;
        debug_assert!(tree.topo.right[n] != LEAF, "a leaf's sphere is its surfel's ball (`sphere`)");
        // Eq. 9 above the refitted subtrees, and for a subtree another thread has claimed
        // (published; Eq. 11 tightens it from the owner's children later, `child_spheres`).
        let (lim, cnt) = (self.params.exact_below.min(MAX_EXACT_BELOW), tree.topo.count[n]);
        // A root whose two children would both be refitted subtrees is refitted with them
        // (module docs, "Subtree refit": small objects).
        let refit = cnt <= lim || (n == 0 && lim > 0 && cnt <= 2 * lim);
        let (c, r) = (if refit { self.refit_subtree(ii, n, exclusive) } else { None })
            .unwrap_or_else(|| tree.update_eq9(n, &ii.field, &ii.obj.nodes.rest, self.params.recentred_bound, self.params.node_rotation));
        ii.nodes.publish(n, c, r, self.frame, exclusive);
        (c, r)
    }

    /// The spheres of inner node `n` (at most `exact_below` surfels) and of its whole subtree,
    /// from their deformed surfels, published at once: every leaf ball is made current
    /// (§4.1.2 updates leaves from their surfel), then, bottom up, each inner node is centred
    /// at the middle of its leaf-ball centres' bounding box (the union of its children's)
    /// with the radius reaching its farthest leaf ball ([`max_reach_x8`]) — Eq. 11 taken down
    /// to the leaves, O(m log m) for m surfels; a node of two or three surfels
    /// ([`ENC_MAX`]) takes the smallest sphere around its two children (Eq. 11 re-centred,
    /// as `tighten`). This deviates from the paper, which uses Eq. 9 for every inner node on
    /// its first visit: at 512×384 the rays deform 93–100 % of the surfels anyway (for the
    /// leaf and MLS tests), and with them in hand an exact sphere costs less than Eq. 9 over
    /// a ≈17-entry node list and is much tighter (module docs, "Subtree refit"). Every leaf
    /// ball lies inside, so hits are unchanged.
    ///
    /// A subtree of more than [`REFIT_CLAIM_MIN`] surfels is refitted by one thread per
    /// frame: `None` tells a thread that finds it claimed to bound `n` by Eq. 9 (valid,
    /// looser; Eq. 11 tightens it once the owner has published the children); the owner
    /// publishes every inner node below `n` that is not already current (a leaf's sphere is
    /// its surfel's ball, made current with the surfel). (Publishing nothing for
    /// `n` until the owner is done was tried: every packet in the meantime recomputed Eq. 9
    /// and refitted the small subtrees below again, 2× slower frames.)
    fn refit_subtree(&self, ii: &Instance, n: usize, exclusive: bool) -> Option<(Vec3, f32)> {
        let topo = &ii.obj.tree.topo;
        let (s0, cnt) = (topo.start[n] as usize, topo.count[n] as usize);
        if cnt > REFIT_CLAIM_MIN as usize && !ii.nodes.slot[n].try_claim(self.frame) {
            return None;
        }
        Some(REFIT_SCRATCH.with(|cell| {
            let mut sc = cell.borrow_mut();
            let RefitScratch { x, y, z, r, lo, hi, sph } = &mut *sc;
            // Every entry below `cnt` is written before it is read, so the buffers only grow
            // (zero-filling them per call cost about 3 % of the whole-ball refits, stop 71);
            // `max_reach_x8` loads whole groups of eight, up to REACH_PAD entries (of any
            // value) past the end.
            for v in [&mut *x, &mut *y, &mut *z, &mut *r] {
                if v.len() < cnt + REACH_PAD {
                    v.resize(cnt + REACH_PAD, 0.0);
                }
            }
            let perm = &topo.perm[s0..s0 + cnt];
            // The used lengths as slices, whose bounds stay in registers across the atomic
            // stores (as the node buffers' below).
            let n8 = cnt + REACH_PAD;
            let (x, y, z, r) = (&mut x[..n8], &mut y[..n8], &mut z[..n8], &mut r[..n8]);
            let (slot, obj, field) = (&ii.surf.slot[..], &*ii.obj, &ii.field);
            // Eight surfels at a time: those not yet current are deformed (Eq. 1) one by
            // one, then their normals and leaf balls computed in one f32x8 pass.
            let mut def = [DeformedSurfel { p: Vec3::ZERO, u: Vec3::ZERO, v: Vec3::ZERO, stretch: 0.0 }; 8];
            let mut todo = [0usize; 8];
            for (ci, chunk) in perm.chunks(8).enumerate() {
                let base = ci * 8;
                let mut m = 0;
                for (j, &s) in chunk.iter().enumerate() {
                    if let Some(&a) = perm.get(base + j + PREFETCH_AHEAD) {
                        prefetch_at(slot, a as usize);
                        prefetch_surfel_inputs(obj, a as usize);
                    }
                    let s = s as usize;
                    if slot[s].stamp.load(Acquire) == self.frame {
                        let (c, rr) = load_surfel_ball(&ii.surf, s);
                        (x[base + j], y[base + j], z[base + j], r[base + j]) = (c.x, c.y, c.z, rr);
                    } else {
                        def[m] = deform_surfel(obj, field, s);
                        todo[m] = base + j;
                        m += 1;
                    }
                }
                if m > 0 {
                    let (nrm, ext) = normal_extent_x8(&def[..m]);
                    for h in 0..m {
                        let (i, d) = (todo[h], &def[h]);
                        let rr = ext[h] * (1.0 + RADIUS_PAD);
                        store_surfel_nr(&ii.surf, perm[i] as usize, d, nrm[h], rr, self.frame);
                        (x[i], y[i], z[i], r[i]) = (d.p.x, d.p.y, d.p.z, rr);
                    }
                }
            }
            // Each inner node's entry is written before its parent reads it (below): grow
            // only. A leaf has no entry: its parent reads its ball from the arrays above.
            let m = 2 * cnt - 1;
            if lo.len() < m {
                lo.resize(m, Vec3A::ZERO);
                hi.resize(m, Vec3A::ZERO);
                sph.resize(m, (Vec3::ZERO, 0.0));
            }
            // The buffers and the subtree's topology as slices of their used lengths, indexed
            // by q − n: their bounds stay in registers across the atomic stores below.
            let (lo, hi, sph) = (&mut lo[..m], &mut hi[..m], &mut sph[..m]);
            let (x, y, z, r) = (&*x, &*y, &*z, &*r);
            let (starts, counts) = (&topo.start[n..n + m], &topo.count[n..n + m]);
            let (balls, slots) = (&ii.ball[n..n + m], &ii.nodes.slot[n..n + m]);
            let ball_at = |a: usize| (Vec3::new(x[a], y[a], z[a]), r[a]);
            // Pre-order: a node's descendants follow it, so descending indices visit every
            // child before its parent.
            for i in (0..m).rev() {
                if i >= PREFETCH_AHEAD {
                    prefetch_at(slots, i - PREFETCH_AHEAD);
                    prefetch_at(balls, i - PREFETCH_AHEAD);
                }
                let (a, k) = (starts[i] as usize - s0, counts[i]);
                if k == 1 {
                    // A leaf: its surfel's ball (§4.1.2), for the traversals' compact reads.
                    balls[i].store(ball_at(a));
                    continue;
                }
                let (q, k) = (n + i, k as usize);
                let (rq, c1, c2) = Topology::split(q, k as u32);
                let (l, rr) = (i + 1, rq - n);
                let pt = |a: usize| Vec3A::new(x[a], y[a], z[a]);
                let (lo_l, hi_l) = if c1 == 1 { (pt(a), pt(a)) } else { (lo[l], hi[l]) };
                let ar = a + c1 as usize;
                let (lo_r, hi_r) = if c2 == 1 { (pt(ar), pt(ar)) } else { (lo[rr], hi[rr]) };
                (lo[i], hi[i]) = (lo_l.min(lo_r), hi_l.max(hi_r));
                // Around two leaf balls the smallest sphere is Eq. 11 re-centred: no reach to
                // compute (nor for three, `ENC_MAX`; its left child is a leaf). Above, only
                // the exact reach from the box centre (stop 71): the sphere around both
                // children, a square root and a division chained up the tree, was the smaller
                // one at 7-10 % of the nodes; without it the sphere tests moved by at most
                // 0.3 % and the whole-ball refits got 10 % faster (BENCHMARKS.md, "Stop 71").
                let b = if k <= ENC_MAX {
                    let s2 = if c2 == 1 { ball_at(ar) } else { sph[rr] };
                    enclosing_sphere(ball_at(a), s2)
                } else {
                    let c = Vec3::from(0.5 * (lo[i] + hi[i]));
                    let reach = max_reach_x8(x, y, z, r, a..a + k, c);
                    (c, reach * (1.0 + RADIUS_PAD) + RADIUS_PAD * c.abs().max_element())
                };
                sph[i] = b;
                // Before q's stamp (below, or the caller's for n): a reader that sees q
                // current finds every ball of q's subtree written (`compact_max`).
                balls[i].store(b);
                if k > REFIT_CLAIM_MIN as usize {
                    // q's whole subtree is written (bottom up): complete, for `compact_children`.
                    slots[i].mark_complete(self.frame);
                }
                if i != 0 && slots[i].stamp.load(Relaxed) != self.frame {
                    // Without the lock where every writer writes these same values: a node
                    // of at most REFIT_CLAIM_MIN surfels is never claimed, so never bounded
                    // by Eq. 9 (any thread that reaches it first refits it, from the same
                    // leaf balls, to the same bits), and one of fewer than exact_below / 2
                    // is never tightened (`child_spheres`). A reader that meets two such
                    // writers mid-write still assembles those values.
                    let plain = exclusive || (k <= REFIT_CLAIM_MIN as usize && 2 * k < self.params.exact_below as usize);
                    ii.nodes.publish(q, b.0, b.1, self.frame, plain);
                }
            }
            sph[0]
        }))
    }

    /// The spheres of inner node n's two children (updating them lazily), and Eq. 11 for n;
    /// `c` is n's surfel count (its children's kinds and the right child follow from it,
    /// [`Topology::split`]) and `known` whether n's subtree is known to be complete (its
    /// parent's is, [`compact_children`](Self::compact_children)). The third value says
    /// whether n's subtree is complete, and so its children's.
    #[inline(always)]
    fn child_spheres(&self, ii: &Instance, nv: Option<&Topology>, n: usize, c: u32, known: bool) -> ((Vec3, f32), (Vec3, f32), bool) {
        let (rc, c1, c2) = Topology::split(n, c);
        let (leaf1, leaf2) = (c1 == 1, c2 == 1);
        let ((s1, s2), compact) = match self.compact_children(ii, nv, n, c, rc, known) {
            Some(b) => (b, true),
            None => {
                self.prefetch_node(ii, nv, rc, leaf2);
                ((self.sphere_as_nv(ii, nv, n + 1, leaf1), self.sphere_as_nv(ii, nv, rc, leaf2)), false)
            }
        };
        // A node inside a refitted subtree took Eq. 11 from its final children when it was
        // refitted (`refit_subtree`), so it is skipped here. Median splits halve the counts,
        // so a node of fewer than exact_below/2 surfels is inside one; a subtree's own root
        // (≥ exact_below/2) may carry the Eq. 9 sphere of a claimed refit and is tightened.
        if nv.is_none() && self.params.eq11 && 2 * c >= self.params.exact_below {
            // n was tested before the descent, so it is current; its centre is read only for
            // the paper's Eq. 11 (the re-centred form encloses the two child spheres).
            let c = if self.params.recentre_eq11 { Vec3::NAN } else { self.sphere_as_nv(ii, None, n, false).0 };
            self.tighten_lazy(ii, n, c, s1, s2);
        }
        (s1, s2, compact)
    }

    /// Starts the load of node n's lazy state (its slot, or its surfel's for a leaf) so
    /// that it overlaps the load of its sibling's.
    #[inline(always)]
    fn prefetch_node(&self, ii: &Instance, nv: Option<&Topology>, n: usize, leaf: bool) {
        if nv.is_some() {
            return;
        }
        if leaf {
            prefetch_at(&ii.surf.slot, ii.obj.tree.topo.surfel[n] as usize);
        } else {
            prefetch_at(&ii.nodes.slot, n);
        }
    }

    /// Of how many surfels at most a current inner node's subtree is complete: every ball
    /// in it written by a subtree refit (module docs, "Compact balls"). Such a node is
    /// never bounded by Eq. 9 (it is refitted, `cnt ≤ exact_below`, and never claimed,
    /// `cnt ≤ REFIT_CLAIM_MIN`), and its refit writes its descendants' balls before it
    /// publishes the node (bottom up, descending pre-order indices), so a reader that saw
    /// its stamp (acquire) reads this frame's balls below it without stamp checks.
    #[inline(always)]
    fn compact_max(&self) -> u32 {
        self.params.exact_below.min(MAX_EXACT_BELOW).min(REFIT_CLAIM_MIN)
    }

    /// The children's spheres of current inner node n (right child `rc`) from the compact
    /// [`Ball`]s, if n's subtree is complete: by its size ([`compact_max`](Self::compact_max)),
    /// because its parent's is (`known`: the refit that wrote the parent's subtree wrote
    /// n's), or because a refit that covered it has finished and said so
    /// ([`NodeSlot::mark_complete`]). Lazy modes only. The balls hold each node's refitted
    /// sphere, no looser than its slot's (which may hold Eq. 9's while a claimed refit
    /// runs): no stamp, lock or branch per child. The traversals pass `known` down
    /// their stacks, so below the first complete node no slot is read at all (stop
    /// 68; the claim's load was a miss on every node of more than 64 surfels there).
    #[inline(always)]
    fn compact_children(
        &self,
        ii: &Instance,
        nv: Option<&Topology>,
        n: usize,
        cnt: u32,
        rc: usize,
        known: bool,
    ) -> Option<((Vec3, f32), (Vec3, f32))> {
        if nv.is_some() {
            return None;
        }
        let complete = known || cnt <= self.compact_max() || (cnt > REFIT_CLAIM_MIN && ii.nodes.slot[n].complete(self.frame));
        complete.then(|| (ii.ball[n + 1].load(), ii.ball[rc].load()))
    }

    /// Starts the load of the far one of node n's two child balls (`c` its count), if n is
    /// an inner node some lane `m` still needs, in a complete subtree.
    #[inline(always)]
    fn prefetch_far_ball(&self, ii: &Instance, n: usize, c: u32, m: u8) {
        if m != 0 && c > 1 {
            prefetch_read_at(&ii.ball, Topology::split(n, c).0);
        }
    }

    /// Starts the loads a leaf test of leaf `n` may need after its surfel's slot: the MLS
    /// neighbour row and support radius, and the collection for the clipping test (lazy
    /// and naive alike). Called once the leaf's sphere is hit, so these misses overlap the
    /// surfel slot's instead of following it: perf put a quarter of `iterate`'s samples on
    /// the row and the radius (stop 67).
    #[inline(always)]
    fn prefetch_leaf(&self, ii: &Instance, topo: &Topology, n: usize) {
        let (obj, s) = (&*ii.obj, topo.surfel[n] as usize);
        prefetch_read_at(&ii.surf.slot, s);
        let row = s * obj.nk;
        prefetch_read_at(&obj.nbr, row);
        prefetch_read_at(&obj.nbr, row + obj.nk - 1);
        prefetch_read_at(&obj.h, s);
        if ii.clipped {
            prefetch_read_at(&obj.coll, s);
        }
    }

    /// §4.4's shadow-ray order at inner node n: whether the left child goes first (it is
    /// current, or neither is; the right one first only when it alone is current).
    #[inline(always)]
    fn left_first(&self, ii: &Instance, l: usize, r: usize) -> bool {
        if self.params.shadow_updated_first && ii.naive.is_none() {
            self.current(ii, l) || !self.current(ii, r)
        } else {
            true
        }
    }

    /// Eq. 11, evaluated at every descent through a node once both children are current
    /// ("if a node is already visited before, update the radius using Equation 11"), so
    /// tightening propagates upwards as the children tighten. With
    /// `TraceParams::recentre_eq11` (default) the node takes the smallest sphere around both
    /// children's spheres, whose centre lies between theirs, instead of the smallest one
    /// around its Eq. 3 centre (the paper's Eq. 11): a deviation that stops the looseness of
    /// spheres of spheres compounding up the levels (`armadillo-ball`, detail 0.4, frame 15:
    /// 8.6 M → 4.7 M sphere tests). Written only when the radius shrinks (see [`NodeSlot`]).
    #[inline]
    fn tighten(&self, ii: &Instance, n: usize, c: Vec3, s1: (Vec3, f32), s2: (Vec3, f32)) {
        if ii.naive.is_some() || !self.params.eq11 {
            return;
        }
        self.tighten_lazy(ii, n, c, s1, s2);
    }

    /// [`tighten`](Self::tighten) for a caller that checked that ii is lazy and Eq. 11 on.
    #[inline]
    fn tighten_lazy(&self, ii: &Instance, n: usize, c: Vec3, s1: (Vec3, f32), s2: (Vec3, f32)) {
        let slot = &ii.nodes.slot[n];
        let cur = f32::from_bits(slot.r.load(Relaxed));
        // No square root on the common path: the enclosing radius is at least
        // (‖c₁ − c₂‖ + r₁ + r₂)/2, so it cannot beat `cur` unless ‖c₁ − c₂‖ < 2·cur − r₁ − r₂.
        let slack = 2.0 * cur - s1.1 - s2.1;
        if !(slack > 0.0 && (s1.0 - s2.0).length_squared() < slack * slack) {
            return;
        }
        let (cc, rr) = if self.params.recentre_eq11 { enclosing_sphere(s1, s2) } else { (c, child_bound(c, s1.0, s1.1, s2.0, s2.1)) };
        if !(rr < cur && rr > 0.0 && slot.try_lock()) {
            return;
        }
        // Under the lock: the node must be this frame's, and the radius still larger.
        if slot.stamp.load(Relaxed) == self.frame && rr < f32::from_bits(slot.r.load(Relaxed)) {
            slot.write(cc, rr);
            if slot.tight.load(Relaxed) != self.frame {
                slot.tight.store(self.frame, Relaxed);
            }
        }
        slot.unlock();
    }

    // -- leaves ----------------------------------------------------------------------------

    /// Any-hit test of leaf `n` of instance `k`: ellipse hit, MLS iteration and clipping.
    fn leaf(&self, k: usize, n: usize, ray: &Ray, dc: &mut DeformCounters, ctr: &mut Counters) -> Option<SurfelHit> {
        let ii = &self.inst[k];
        let s = self.topo(ii).surfel[n] as usize;
        self.leaf_surfel(k, s, leaf_node(ii, n), ray, dc, ctr)
    }

    /// [`leaf`](Self::leaf) for the lanes `m` of a packet (one x8 ellipse test): the mask of
    /// lanes with an accepted hit.
    #[allow(clippy::too_many_arguments)]
    fn leaf_x8(
        &self,
        k: usize,
        n: usize,
        rays: &[Ray],
        pk: &RayPacketX8,
        m: u8,
        tfar: f32x8,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
    ) -> u8 {
        let ii = &self.inst[k];
        let (s, node) = (self.topo(ii).surfel[n] as usize, leaf_node(ii, n));
        let (ds, hit, t, x) = self.ellipse_x8(k, s, pk, m, tfar, dc, ctr);
        let mut acc = 0u8;
        for i in lanes(hit) {
            let x0 = Vec3::new(x[0][i], x[1][i], x[2][i]);
            if self.iterate(k, s, node, &rays[i], &ds, (t[i], x0), dc).is_some() {
                acc |= 1 << i;
            }
        }
        acc
    }

    /// [`leaf`](Self::leaf) by surfel; `node` is reported in the hit (for the cache).
    fn leaf_surfel(&self, k: usize, s: usize, node: u32, ray: &Ray, dc: &mut DeformCounters, ctr: &mut Counters) -> Option<SurfelHit> {
        let (ds, t0, x0) = self.ellipse(k, s, ray, dc, ctr)?;
        self.iterate(k, s, node, ray, &ds, (t0, x0), dc)
    }

    /// Closest-hit visit of surfel `s`'s leaf (`node`), by the search's [`Rule`]. Under the
    /// nearest-ellipse rules a surfel of a clipped collection (§4.3) is iterated at once and
    /// ordered by its MLS `t`, like the paper's rule: most of its ellipse hits end clipped,
    /// and each rejected candidate would cost the ray another pass.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn visit(&self, k: usize, s: usize, node: u32, ray: &Ray, best: &mut Best, dc: &mut DeformCounters, ctr: &mut Counters) {
        let Some((ds, t0, x0)) = self.ellipse(k, s, ray, dc, ctr) else {
            return;
        };
        self.visit_hit(k, s, node, ray, best, &ds, (t0, x0), dc);
    }

    /// [`visit`](Self::visit) after the ray has hit surfel `s`'s ellipse at `(t0, x0)`.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn visit_hit(
        &self,
        k: usize,
        s: usize,
        node: u32,
        ray: &Ray,
        best: &mut Best,
        ds: &DeformedSurfel,
        (t0, x0): (f32, Vec3),
        dc: &mut DeformCounters,
    ) {
        let ii = &self.inst[k];
        if best.rule == Rule::EveryMls || clipped_surfel(ii, s) {
            if let Some(h) = self.iterate(k, s, node, ray, ds, (t0, x0), dc) {
                best.offer(h, h.t);
            }
            return;
        }
        let (kk, ss) = (k as u32, s as u32);
        if best.rule == Rule::Deferred {
            best.propose(Cand { t0, k: kk, s: ss, node });
        } else if best.above_floor(t0, kk, ss) && best.beaten_by(t0, kk, ss) {
            if let Some(h) = self.iterate(k, s, node, ray, ds, (t0, x0), dc) {
                best.offer(h, t0);
            }
        }
    }

    /// The ellipse of surfel `s` against the lanes `m` of a packet ([`RayPacketX8::ellipse`]:
    /// one fetch of the surfel, one x8 test, bit-identical to [`ellipse`](Self::ellipse) per
    /// ray): the deformed surfel and the hit lanes with their `(t0, x0)`. Counts a leaf test
    /// per lane, as `ellipse` does.
    #[allow(clippy::too_many_arguments)]
    #[inline]
    fn ellipse_x8(
        &self,
        k: usize,
        s: usize,
        pk: &RayPacketX8,
        m: u8,
        tfar: f32x8,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
    ) -> (DeformedSurfel, u8, [f32; 8], [[f32; 8]; 3]) {
        let ii = &self.inst[k];
        if ii.clipped {
            // The clipping neighbours' row, which the clip test after a hit reads first; its
            // collection was prefetched with the leaf (`prefetch_leaf`).
            let obj = &*ii.obj;
            let c = obj.coll[s] as usize;
            let np = obj.clip_partners[c].len();
            if np > 0 {
                prefetch_read_at(&obj.clip_nb, obj.clip_base[c] + (s - obj.model.collections[c].start as usize) * np);
            }
        }
        let ds = self.surfel(ii, s);
        let cnt = m.count_ones() as u64;
        dc.leaf_tests += cnt;
        ctr.add(Counter::surfel_tests, cnt);
        let (hit, t, x) = pk.ellipse(ds.p, ds.u, ds.v, tfar);
        (ds, hit & m, t.to_array(), [x[0].to_array(), x[1].to_array(), x[2].to_array()])
    }

    /// After a traversal pass: iterates the deferred candidate (if any). Returns whether the
    /// ray needs another pass (its candidate was rejected).
    fn resolve(&self, ray: &Ray, best: &mut Best, dc: &mut DeformCounters) -> bool {
        let Some(c) = best.cand.take() else {
            return false;
        };
        let (k, s) = (c.k as usize, c.s as usize);
        let ds = self.surfel(&self.inst[k], s);
        // The same (current) surfel and ray give the same ellipse hit as in the pass.
        let hit = ellipse_hit(ray.org, ray.dir, ds.p, ds.u, ds.v, ray.tnear, ray.tfar)
            .and_then(|(t0, x0)| self.iterate(k, s, c.node, ray, &ds, (t0, x0), dc));
        match hit {
            Some(h) => {
                best.hit = Some(h);
                best.t = c.t0;
                false
            }
            None => {
                best.floor = (c.t0, c.k, c.s);
                best.t = best.tfar;
                best.hit = None;
                best.passes += 1;
                if best.passes >= MAX_DEFERRED_PASSES {
                    best.rule = Rule::AboveFloor;
                }
                true
            }
        }
    }

    /// The ray's hit with surfel `s`'s ellipse in [tnear, tfar]: (the deformed surfel, t0,
    /// point). Counts a leaf test.
    #[inline]
    fn ellipse(&self, k: usize, s: usize, ray: &Ray, dc: &mut DeformCounters, ctr: &mut Counters) -> Option<(DeformedSurfel, f32, Vec3)> {
        let ds = self.surfel(&self.inst[k], s);
        dc.leaf_tests += 1;
        ctr.inc(Counter::surfel_tests);
        // Ellipse and MLS run over the ray's whole interval, not [tnear, best t]: an
        // iteration may pass beyond the current best and still converge in front of it, and
        // the result must not depend on the order in which leaves are visited. The best hit
        // so far only culls the result (`Best::offer`).
        let (t0, x0) = ellipse_hit(ray.org, ray.dir, ds.p, ds.u, ds.v, ray.tnear, ray.tfar)?;
        Some((ds, t0, x0))
    }

    /// MLS iteration (§4.2.1) from the ellipse hit `(t0, x0)` of surfel `s`, then clipping
    /// (§4.3).
    #[allow(clippy::too_many_arguments)]
    fn iterate(
        &self,
        k: usize,
        s: usize,
        node: u32,
        ray: &Ray,
        ds: &DeformedSurfel,
        (t0, x0): (f32, Vec3),
        dc: &mut DeformCounters,
    ) -> Option<SurfelHit> {
        let ii = &self.inst[k];
        let obj = &ii.obj;
        let (sc, sr) = leaf_sphere(ds);
        // The ball around sc that holds every point the iteration may return: the leaf ball,
        // which bounds the points it moves to, and the start point x0, which it does not
        // (in the ellipse, up to the rounding of o + d·t: far from the camera's origin that
        // exceeds `ball_clipped`'s margin on a small splat; review finding, stop 80, test
        // `early_clip_bounds_the_start_point_too`).
        if ii.clipped && self.params.clip_early && self.ball_clipped(ii, s, sc, sr.max((x0 - sc).length())) {
            dc.clipped_early += 1;
            return None;
        }
        // The iteration runs relative to the leaf's centre: its convergence test compares
        // |f(x)| with eps_rel·h, which absolute coordinates cannot resolve far from the
        // origin (at 300 units their rounding is 3e-5, ε for h = 0.05 is 5e-6: every
        // iteration ran out and the surface got holes; review finding, stop 49, test
        // `objects_far_from_the_origin_are_hit_as_near_it`). The ray, too, starts at the
        // ellipse hit x0 (its parameter counted from t0): from the camera's origin each step's
        // x = o + d·t carried the rounding of |o − sc|, the camera's distance, and 3,000 units
        // from a ball with h = 0.15 a third of the rays that hit missed (review finding, stop
        // 77, test `a_far_camera_sees_the_surface_as_a_near_one`).
        let mut nb = MlsNbr::default();
        let nk = obj.nk.min(MAX_NBR);
        let nbr = &obj.nbr[s * obj.nk..s * obj.nk + nk];
        // All the neighbours' slots are requested before the first is read: the loop below
        // branches on each stamp (and may deform), which kept its loads from overlapping.
        for &q in nbr.iter().take_while(|&&q| q != NO_NBR) {
            prefetch_at(&ii.surf.slot, q as usize);
        }
        for q in nbr.iter().take_while(|&&q| q != NO_NBR) {
            let (p, n) = self.surfel_pn(ii, *q as usize);
            nb.push(p - sc, n);
        }
        let h = obj.h[s] * ds.stretch.clamp(1.0, self.params.max_support_stretch);
        dc.mls_runs += 1;
        let xr = x0 - sc;
        match mls_intersect_x8(xr, ray.dir, 0.0, xr, &nb, h, Vec3::ZERO, sr, ray.tnear - t0, ray.tfar - t0, &self.params.mls) {
            MlsOutcome::Rejected { iters } => {
                dc.mls_iterations += iters as u64;
                dc.mls_rejected += 1;
                None
            }
            MlsOutcome::Hit { t, p, n: nrm, iters } => {
                let (t, p) = (t0 + t, p + sc);
                dc.mls_iterations += iters as u64;
                dc.mls_hits += 1;
                let c = obj.coll[s];
                for slot in 0..obj.clip_partners[c as usize].len() {
                    let [a, b] = obj.clip_pair(s, slot);
                    let ((pa, na), (pb, nb)) = (self.surfel_pn(ii, a as usize), self.surfel_pn(ii, b as usize));
                    if clipped_by(p, pa, na, pb, nb) {
                        dc.clipped += 1;
                        return None;
                    }
                }
                Some(SurfelHit { t, p, n: nrm, instance: k as u32, surfel: s as u32, collection: c, node, iterations: iters, t0 })
            }
        }
    }

    /// Whether every point of the ball `(sc, sr)` around surfel `s` is clipped (§4.3) by one
    /// of its partner surfaces: the ball lies more than its radius in front of both clipping
    /// neighbours' tangent planes. `iterate` passes a ball that holds every point an MLS hit
    /// from `s` may lie at (the leaf ball, which `mls_intersect_x8` holds the moved points
    /// to, and the start point), and there `clipped_by` sees both distances positive: the hit
    /// would be clipped, so the iteration is skipped (not in the paper; same hits, since the
    /// clipping test at the hit would reject it anyway). On `heads` most ellipse hits of
    /// the clipped surfaces are such (the part of a surface inside another).
    #[inline]
    fn ball_clipped(&self, ii: &Instance, s: usize, sc: Vec3, sr: f32) -> bool {
        let obj = &ii.obj;
        // A margin over rounding: the hit is computed relative to sc, its distances at
        // absolute coordinates; stored normals are unit (or zero: never clipped here, as in
        // `clipped_by`'s both-positive case), within far less than the 0.1 %.
        let m = sr * 1.001 + 1e-6 * sc.abs().max_element();
        let np = obj.clip_partners[obj.coll[s] as usize].len();
        // Every partner's two slots requested before the first is read (as the MLS
        // neighbours': the test below branches on each).
        for slot in 0..np {
            for q in obj.clip_pair(s, slot) {
                prefetch_read_at(&ii.surf.slot, q as usize);
            }
        }
        (0..np).any(|slot| {
            let [a, b] = obj.clip_pair(s, slot);
            let ((pa, na), (pb, nb)) = (self.surfel_pn(ii, a as usize), self.surfel_pn(ii, b as usize));
            na.dot(sc - pa) > m && nb.dot(sc - pb) > m
        })
    }

    // -- closest hit -----------------------------------------------------------------------

    /// Closest hit; `slot` selects the per-ray cache entry (LazyCache; ignored otherwise).
    pub fn intersect(&self, ray: &Ray, slot: Option<u32>, ctr: &mut Counters) -> Option<SurfelHit> {
        self.intersect_ex(ray, slot, ctr, &mut DeformCounters::default())
    }

    /// The extent of the surfel whose leaf produced `hit` (its ellipse's longer semi-axis in
    /// this frame): the local sample spacing, which sets how far a secondary ray must leave
    /// the surface to clear the neighbouring splats (see `lodtrace animate`'s shading).
    pub fn hit_extent(&self, hit: &SurfelHit) -> f32 {
        let ii = &self.inst[hit.instance as usize];
        self.surfel(ii, hit.surfel as usize).extent()
    }

    /// [`intersect`](Self::intersect) with the tracer's own counters.
    pub fn intersect_ex(&self, ray: &Ray, slot: Option<u32>, ctr: &mut Counters, dc: &mut DeformCounters) -> Option<SurfelHit> {
        if !traceable(ray) || self.frame == 0 {
            return None;
        }
        let mut best = Best::new(ray.tfar, self.params.nearest_ellipse);
        if self.mode == UpdateMode::Refit {
            loop {
                self.refit_traverse(ray, &mut best, false, dc, ctr);
                if !self.resolve(ray, &mut best, dc) {
                    return best.hit;
                }
            }
        }
        let slot = if self.mode == UpdateMode::LazyCache { slot.filter(|s| (*s as usize) < self.cache.len()) } else { None };
        let mut first = true;
        loop {
            let skip = match slot.filter(|_| self.cache_look) {
                Some(sl) => self.search_cached(sl, ray, &mut best, first, dc, ctr),
                None => (u32::MAX, u32::MAX),
            };
            let roots = self.root_hits(ray, best.t, dc, ctr);
            for (te, k) in roots {
                if te > best.t {
                    continue;
                }
                let sk = if skip.0 == k as u32 { skip.1 } else { u32::MAX };
                self.closest_in(k, ray, 0, te, &mut best, sk, dc, ctr);
            }
            if !self.resolve(ray, &mut best, dc) {
                break;
            }
            // A rejected candidate: the next pass searches everything above it.
            first = false;
        }
        if let Some(sl) = slot.filter(|_| self.cache_keep) {
            self.store_cache(sl, best.hit);
        }
        best.hit
    }

    /// Test reference for [`intersect`](Self::intersect): the closest hit by the rule's
    /// definition, found without a hierarchy — every surfel of every instance is tested and
    /// every ellipse hit iterated, and the accepted hit with the smallest (key, instance,
    /// surfel) wins, the key being `t0` under the nearest-ellipse rule (except for clipped
    /// collections) and the MLS `t` otherwise. Slow: for tests.
    pub fn closest_brute(&self, ray: &Ray) -> Option<SurfelHit> {
        if !traceable(ray) || self.frame == 0 {
            return None;
        }
        let (mut dc, mut ctr) = (DeformCounters::default(), Counters::default());
        let mut best: Option<(f32, u32, u32, SurfelHit)> = None;
        for (k, ii) in self.inst.iter().enumerate() {
            for s in 0..ii.obj.surfel_count() {
                let Some(h) = self.leaf_surfel(k, s, u32::MAX, ray, &mut dc, &mut ctr) else {
                    continue;
                };
                let key = if self.params.nearest_ellipse && !clipped_surfel(ii, s) { h.t0 } else { h.t };
                if best.as_ref().is_none_or(|b| (key, k as u32, s as u32) < (b.0, b.1, b.2)) {
                    best = Some((key, k as u32, s as u32, h));
                }
            }
        }
        best.map(|b| b.3)
    }

    /// §4.2.2: searches the subtree cached in `slot` (if any) into `best`; returns the
    /// (instance, node) that the traversal from the root must then leave out.
    /// Every pass of a ray searches it again (`first`: the ray's first pass, which counts the
    /// lookup and the hit).
    #[inline(always)]
    fn search_cached(&self, sl: u32, ray: &Ray, best: &mut Best, first: bool, dc: &mut DeformCounters, ctr: &mut Counters) -> (u32, u32) {
        // Most slots are empty (their ray hit nothing last frame): checked inline, the search
        // out of line.
        match self.cache[sl as usize].load(Relaxed) {
            NO_CACHE => (u32::MAX, u32::MAX),
            v => self.search_cached_node(v, ray, best, first, dc, ctr),
        }
    }

    /// Requests what the packet's cache searches will read, lane by lane, before the first
    /// of them runs: each lookup is a chain of three loads (the slot, the cached node's
    /// topology, its surfel's or its own lazy state), most of them misses, and searched one
    /// ray after another the eight chains ran one after another. Stage by stage, a stage's
    /// eight loads overlap.
    ///
    /// The slot's own line comes first: perf put 60 % of this function's samples on that
    /// load, a miss per packet (the slots are 1.5 MB at 512×384, written a frame ago), so
    /// each lane at the start of a line also requests the line [`CACHE_AHEAD`] slots on,
    /// which a caller that walks its pixels in rows (`lodtrace animate`) reads a few
    /// packets later (stop 68). A caller with other slots loses nothing but the hint.
    #[inline(never)]
    fn prefetch_cached(&self, slot: &[Option<u32>; 8], valid: u8) {
        let mut v = [NO_CACHE; 8];
        for i in lanes(valid) {
            if let Some(sl) = slot[i] {
                if sl % 8 == 0 {
                    if let Some(a) = self.cache.get(sl as usize + CACHE_AHEAD) {
                        prefetch_read(a);
                    }
                }
                v[i] = self.cache[sl as usize].load(Relaxed);
            }
        }
        let node = |v: u64| -> Option<(&Instance, usize)> {
            let (k, n) = ((v >> 32) as usize, (v & 0xffff_ffff) as usize);
            let ii = self.inst.get(k)?;
            (v != NO_CACHE && n < ii.obj.tree.len()).then_some((ii, n))
        };
        for &x in &v {
            if let Some((ii, n)) = node(x) {
                let topo = &ii.obj.tree.topo;
                prefetch_at(&topo.right, n);
                prefetch_at(&topo.surfel, n);
            }
        }
        for &x in &v {
            if let Some((ii, n)) = node(x) {
                // A leaf (the default cache holds leaves) keeps its sphere with its surfel.
                match ii.obj.tree.topo.surfel[n] {
                    u32::MAX => prefetch_at(&ii.nodes.slot, n),
                    s => prefetch_at(&ii.surf.slot, s as usize),
                }
            }
        }
    }

    /// [`search_cached`](Self::search_cached) for a slot holding `v` (instance << 32 | node).
    #[inline(never)]
    fn search_cached_node(
        &self,
        v: u64,
        ray: &Ray,
        best: &mut Best,
        first: bool,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
    ) -> (u32, u32) {
        let (k, n) = ((v >> 32) as usize, (v & 0xffff_ffff) as usize);
        if k >= self.inst.len() || n >= self.inst[k].obj.tree.len() {
            return (u32::MAX, u32::MAX);
        }
        dc.cache_lookups += first as u64;
        let (ii, topo) = (&self.inst[k], &self.inst[k].obj.tree.topo);
        let search = |n: usize, best: &mut Best, dc: &mut DeformCounters, ctr: &mut Counters| {
            let (c, r) = self.sphere(ii, n);
            dc.sphere_tests += 1;
            dc.tests_at(topo.level[n], 1);
            ctr.inc(Counter::node_tests);
            if let Some(te) = sphere_test_1(ray.org, ray.dir, c, r, ray.tnear, best.t) {
                self.closest_in(k, ray, n as u32, te, best, u32::MAX, dc, ctr);
            }
        };
        search(n, best, dc, ctr);
        // The climb: the subtree of `top` has been searched; while it held no hit, the
        // other child of its parent is searched too, and the parent's whole subtree is then
        // the one the root's traversal skips.
        let mut top = n;
        while self.params.cache_climb && !best.found() && topo.parent[top] != u32::MAX {
            let p = topo.parent[top] as usize;
            search(if top == p + 1 { topo.right[p] as usize } else { p + 1 }, best, dc, ctr);
            top = p;
        }
        if first && best.found() {
            dc.cache_hits += 1;
        }
        (k as u32, top as u32)
    }

    /// Remembers the node of `hit` (`cache_up` levels above its leaf) for the slot's next frame.
    fn store_cache(&self, sl: u32, hit: Option<SurfelHit>) {
        let v = match hit {
            Some(h) => {
                let topo = &self.inst[h.instance as usize].obj.tree.topo;
                let mut n = h.node;
                for _ in 0..self.params.cache_up {
                    match topo.parent[n as usize] {
                        u32::MAX => break,
                        p => n = p,
                    }
                }
                ((h.instance as u64) << 32) | n as u64
            }
            None => NO_CACHE,
        };
        // Most slots keep their value (no hit, frame after frame): a write only on a change
        // keeps those lines clean.
        let c = &self.cache[sl as usize];
        if c.load(Relaxed) != v {
            c.store(v, Relaxed);
        }
    }

    /// Root spheres of all instances, 8 per f32x8 step: (entry, instance) of those hit,
    /// nearest first.
    fn root_hits(&self, ray: &Ray, tfar: f32, dc: &mut DeformCounters, ctr: &mut Counters) -> Vec<(f32, usize)> {
        let mut out = Vec::new();
        let mut cand = Vec::with_capacity(self.inst.len());
        let top_tests = self.top.candidates_1(ray, tfar, &mut cand);
        dc.sphere_tests += top_tests;
        ctr.add(Counter::node_tests, top_tests);
        for chunk in cand.chunks(8) {
            let (mut cx, mut cy, mut cz, mut r) = ([0f32; 8], [0f32; 8], [0f32; 8], [-1f32; 8]);
            let m = chunk.len();
            for (j, &k) in chunk.iter().enumerate() {
                let (c, rr) = self.sphere(&self.inst[k as usize], 0);
                cx[j] = c.x;
                cy[j] = c.y;
                cz[j] = c.z;
                r[j] = rr;
            }
            let (mask, entry) = sphere_test_spheres(ray.org, ray.dir, &cx, &cy, &cz, &r, ray.tnear, tfar);
            dc.sphere_tests += m as u64;
            dc.tests_at(0, m as u64);
            ctr.add(Counter::node_tests, m as u64);
            for (j, &k) in chunk.iter().enumerate() {
                if mask & (1 << j) != 0 && r[j] >= 0.0 {
                    out.push((entry[j], k as usize));
                }
            }
        }
        out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        out
    }

    #[allow(clippy::too_many_arguments)]
    /// Front-to-back traversal of the subtree of `start` (already hit with entry `entry`);
    /// the subtree of `skip` (already searched: the cached node) is left out.
    fn closest_in(
        &self,
        k: usize,
        ray: &Ray,
        start: u32,
        entry: f32,
        best: &mut Best,
        skip: u32,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
    ) {
        let ii = &self.inst[k];
        let topo = self.topo(ii);
        // A leaf (the per-ray cache's node, `cache_up` 0) needs no stack: no allocation per
        // cached ray.
        if topo.right[start as usize] == LEAF {
            if !(entry > best.t) && start != skip {
                self.visit(k, topo.surfel[start as usize] as usize, leaf_node(ii, start as usize), ray, best, dc, ctr);
            }
            return;
        }
        let mut stack: Vec<(u32, f32)> = Vec::with_capacity(64);
        stack.push((start, entry));
        let (o, d) = (ray.org, ray.dir);
        while let Some((n, te)) = stack.pop() {
            if te > best.t {
                continue;
            }
            if n == skip {
                continue;
            }
            let n = n as usize;
            if topo.count[n] == 1 {
                self.visit(k, topo.surfel[n] as usize, leaf_node(ii, n), ray, best, dc, ctr);
                continue;
            }
            let (l, r) = (n + 1, topo.right_child(n));
            let (s1, s2, _) = self.child_spheres(ii, ii.naive.as_ref(), n, topo.count[n], false);
            dc.sphere_tests += 2;
            dc.tests_at(topo.level[l], 2);
            ctr.add(Counter::node_tests, 2);
            let e1 = sphere_test_1(o, d, s1.0, s1.1, ray.tnear, best.t);
            let e2 = sphere_test_1(o, d, s2.0, s2.1, ray.tnear, best.t);
            match (e1, e2) {
                (Some(a), Some(b)) => {
                    if a <= b || !self.params.ordered {
                        stack.push((r as u32, b));
                        stack.push((l as u32, a));
                    } else {
                        stack.push((l as u32, a));
                        stack.push((r as u32, b));
                    }
                }
                (Some(a), None) => stack.push((l as u32, a)),
                (None, Some(b)) => stack.push((r as u32, b)),
                (None, None) => {}
            }
        }
    }

    // -- any hit ---------------------------------------------------------------------------

    /// Any accepted hit in [tnear, tfar]?
    pub fn occluded(&self, ray: &Ray, ctr: &mut Counters) -> bool {
        self.occluded_ex(ray, ctr, &mut DeformCounters::default())
    }

    pub fn occluded_ex(&self, ray: &Ray, ctr: &mut Counters, dc: &mut DeformCounters) -> bool {
        if !traceable(ray) || self.frame == 0 {
            return false;
        }
        let w0 = dc.sphere_tests + dc.leaf_tests;
        let occluded = self.occluded_scalar(ray, ctr, dc);
        dc.shadow_rays += 1;
        dc.shadow_occluded += occluded as u64;
        dc.shadow_tests += dc.sphere_tests + dc.leaf_tests - w0;
        occluded
    }

    /// The body of [`occluded_ex`](Self::occluded_ex) (which counts the shadow ray).
    fn occluded_scalar(&self, ray: &Ray, ctr: &mut Counters, dc: &mut DeformCounters) -> bool {
        if self.mode == UpdateMode::Refit {
            let mut best = Best::new(ray.tfar, self.params.nearest_ellipse);
            return self.refit_traverse(ray, &mut best, true, dc, ctr);
        }
        let mut roots = self.root_hits(ray, ray.tfar, dc, ctr);
        dc.shadow_entered += !roots.is_empty() as u64;
        // The instances whose root sphere holds the origin last ([`own_last`]).
        roots.sort_by_key(|&(e, _)| e <= ray.tnear);
        let mut stack: Vec<u32> = Vec::with_capacity(64);
        for (_, k) in roots {
            let ii = &self.inst[k];
            let topo = self.topo(ii);
            stack.clear();
            // The root was tested: start from its children (or the root itself if a leaf).
            if topo.right[0] == LEAF {
                if self.leaf(k, 0, ray, dc, ctr).is_some() {
                    return true;
                }
                continue;
            }
            let push_children = |stack: &mut Vec<u32>, n: usize| {
                let (l, r) = (n + 1, topo.right_child(n));
                if self.left_first(ii, l, r) {
                    stack.push(r as u32);
                    stack.push(l as u32);
                } else {
                    stack.push(l as u32);
                    stack.push(r as u32);
                }
            };
            push_children(&mut stack, 0);
            while let Some(n) = stack.pop() {
                let n = n as usize;
                let (c, r) = self.sphere(ii, n);
                dc.sphere_tests += 1;
                dc.tests_at(topo.level[n], 1);
                ctr.inc(Counter::node_tests);
                if sphere_test_1(ray.org, ray.dir, c, r, ray.tnear, ray.tfar).is_none() {
                    continue;
                }
                if topo.count[n] == 1 {
                    if self.leaf(k, n, ray, dc, ctr).is_some() {
                        return true;
                    }
                } else {
                    push_children(&mut stack, n);
                }
            }
        }
        false
    }

    // -- packets of eight rays -------------------------------------------------------------

    /// Closest hits of up to eight rays (`slots` as in [`intersect`](Self::intersect), one
    /// per ray), traversed together: a node's sphere is fetched (and lazily updated) once and
    /// tested against all rays still active in it in one [`RayPacketX8`] step; a leaf's ellipse
    /// too (`ellipse_x8`), the MLS iteration then ray by ray. The hits equal
    /// [`intersect_ex`](Self::intersect_ex)'s for every ray
    /// (the closest accepted hit does not depend on the traversal order, module docs), so
    /// images are identical; `sphere_tests` counts one per active ray and sphere, as there.
    /// The children are visited nearer-first by the smallest entry over the rays that hit
    /// them. `Refit` traces the rays one by one.
    pub fn intersect_x8(&self, rays: &[Ray], slots: &[Option<u32>], ctr: &mut Counters, dc: &mut DeformCounters) -> [Option<SurfelHit>; 8] {
        assert!(rays.len() <= 8 && slots.len() == rays.len(), "a packet holds at most 8 rays, one slot each");
        let mut out = [None; 8];
        if self.mode == UpdateMode::Refit || self.frame == 0 {
            for (i, r) in rays.iter().enumerate() {
                out[i] = self.intersect_ex(r, slots[i], ctr, dc);
            }
            return out;
        }
        let valid = valid_mask(rays);
        if valid == 0 {
            return out;
        }
        let mut best = [Best::new(f32::NEG_INFINITY, self.params.nearest_ellipse); 8];
        for i in lanes(valid) {
            best[i] = Best::new(rays[i].tfar, self.params.nearest_ellipse);
        }
        // The slots of the lanes, if this frame looks the cache up or stores into it (the
        // cache gate, `TraceParams::cache_gate`).
        let (look, keep) = (self.mode == UpdateMode::LazyCache && self.cache_look, self.mode == UpdateMode::LazyCache && self.cache_keep);
        let mut slot = [None; 8];
        if look || keep {
            for i in lanes(valid) {
                slot[i] = slots[i].filter(|s| (*s as usize) < self.cache.len());
            }
        }
        let (mut active, mut first) = (valid, true);
        let mut sc = take_scratch();
        let tfar = f32x8::from(std::array::from_fn::<f32, 8, _>(|i| if valid & (1 << i) != 0 { rays[i].tfar } else { f32::NEG_INFINITY }));
        if look {
            self.prefetch_cached(&slot, valid);
        }
        loop {
            // §4.2.2: each ray's cached node first, as in `intersect_ex`.
            let mut skip = [(u32::MAX, u32::MAX); 8];
            if look {
                for i in lanes(active) {
                    if let Some(sl) = slot[i] {
                        skip[i] = self.search_cached(sl, &rays[i], &mut best[i], first, dc, ctr);
                    }
                }
            }
            let pk = packet(rays, active);
            self.root_hits_x8(&pk, active, best_t(&best), dc, ctr, &mut sc.roots);
            for &(_, k, m, e) in &sc.roots {
                // One copy of the loop per kind of tree, so no node checks `ii.naive` again.
                match &self.inst[k].naive {
                    Some(t) => self.closest_in_x8(k, Some(t), rays, &pk, m, e, &mut best, &skip, dc, ctr, &mut sc.stack, tfar),
                    None => self.closest_in_x8(k, None, rays, &pk, m, e, &mut best, &skip, dc, ctr, &mut sc.stack, tfar),
                }
            }
            let mut again = 0u8;
            for i in lanes(active) {
                if self.resolve(&rays[i], &mut best[i], dc) {
                    again |= 1 << i;
                }
            }
            if again == 0 {
                break;
            }
            // Rays whose candidate was rejected search everything above it again.
            active = again;
            first = false;
        }
        PACKET_SCRATCH.set(sc);
        for i in lanes(valid) {
            if let Some(sl) = slot[i].filter(|_| keep) {
                self.store_cache(sl, best[i].hit);
            }
            out[i] = best[i].hit;
        }
        out
    }

    /// Packet form of [`root_hits`](Self::root_hits): the instances along the rays `valid` of
    /// `pk` (instance tree, then each candidate's root sphere against the lanes that reach
    /// it) as (nearest entry, instance, lanes hit, entries), nearest first.
    fn root_hits_x8(
        &self,
        pk: &RayPacketX8,
        valid: u8,
        tfar: f32x8,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
        roots: &mut Vec<(f32, usize, u8, f32x8)>,
    ) {
        roots.clear();
        let mut root_tests = 0;
        let mut root = |k: u32, lm: u8| {
            let k = k as usize;
            let (c, r) = self.sphere(&self.inst[k], 0);
            root_tests += lm.count_ones() as u64;
            let (m, e) = pk.test(c, r, tfar);
            let m = m & lm;
            if m != 0 {
                roots.push((hmin(e, m), k, m, e));
            }
        };
        // Few instances: the packet's cone against all their spheres, eight per step.
        let cone = if self.top.has_flat() { PacketCone::new(pk, valid, tfar) } else { None };
        let top_tests = match cone {
            Some(cone) => self.top.candidates_cone(&cone, |k| root(k, valid)),
            None => self.top.candidates_x8(pk, valid, tfar, root),
        };
        dc.sphere_tests += top_tests + root_tests;
        dc.tests_at(0, root_tests);
        ctr.add(Counter::node_tests, top_tests + root_tests);
        roots.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    }

    /// Packet form of [`closest_in`](Self::closest_in) from the root of instance `k`; `nv`
    /// is instance k's naive tree if any (the caller passes `Some`/`None` literally, so each
    /// kind of tree gets its own inlined copy of the loop).
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn closest_in_x8(
        &self,
        k: usize,
        nv: Option<&Topology>,
        rays: &[Ray],
        pk: &RayPacketX8,
        mask: u8,
        entry: f32x8,
        best: &mut [Best; 8],
        skip: &[(u32, u32); 8],
        dc: &mut DeformCounters,
        ctr: &mut Counters,
        stack: &mut Vec<(u32, u32, u8, u8, f32x8)>,
        tfar: f32x8,
    ) {
        let ii = &self.inst[k];
        let topo = nv.unwrap_or(&ii.obj.tree.topo);
        let skipn: [u32; 8] = std::array::from_fn(|i| if skip[i].0 == k as u32 { skip[i].1 } else { u32::MAX });
        let any_skip = skipn.iter().any(|&s| s != u32::MAX);
        let skip8 = u32x8::from(skipn);
        let mut tb = best_t(best);
        stack.clear();
        // (node, its surfel count, its level | COMPLETE, lanes, entries): the level rides on
        // the stack for `level_tests`, the count for the node's kind and children
        // ([`Topology::split`]) and the flag for a subtree known to be complete
        // (`compact_children`), rather than costing a load per node.
        stack.push((0, topo.count[0], 0, mask, entry));
        while let Some((n, c, lv, m, te)) = stack.pop() {
            let (leaf, known, lv) = (c == 1, lv & COMPLETE != 0, lv & !COMPLETE);
            let mut m = m & te.simd_le(tb).to_bitmask() as u8;
            if any_skip {
                // The lanes whose cached node (searched already) this is, in one compare.
                m &= !(skip8.simd_eq(u32x8::splat(n)).to_bitmask() as u8);
            }
            if m == 0 {
                continue;
            }
            let n = n as usize;
            if leaf {
                let (node, s) = (leaf_node_of(nv.is_some(), n), topo.surfel[n] as usize);
                let (ds, hit, t, x) = self.ellipse_x8(k, s, pk, m, tfar, dc, ctr);
                for i in lanes(hit) {
                    let x0 = Vec3::new(x[0][i], x[1][i], x[2][i]);
                    self.visit_hit(k, s, node, &rays[i], &mut best[i], &ds, (t[i], x0), dc);
                }
                tb = best_t(best);
                continue;
            }
            let (l, (r, c1, c2)) = (n + 1, Topology::split(n, c));
            let (leaf1, leaf2) = (c1 == 1, c2 == 1);
            let (s1, s2, compact) = self.child_spheres(ii, nv, n, c, known);
            // The children's level; past LEVELS − 1 they share the counters' last level
            // anyway.
            let lv = lv.min(LEVELS as u8 - 2) + 1;
            let cnt = 2 * m.count_ones() as u64;
            dc.sphere_tests += cnt;
            dc.tests_below(lv, cnt);
            ctr.add(Counter::node_tests, cnt);
            let (m1, e1) = pk.test(s1.0, s1.1, tb);
            let (m2, e2) = pk.test(s2.0, s2.1, tb);
            let (m1, m2) = (m1 & m, m2 & m);
            if leaf1 && m1 != 0 {
                self.prefetch_leaf(ii, topo, l);
            }
            if leaf2 && m2 != 0 {
                self.prefetch_leaf(ii, topo, r);
            }
            if compact {
                // The far one of a hit inner child's two child balls (the near one shares
                // the child's own line), a level ahead of its visit.
                self.prefetch_far_ball(ii, l, c1, m1);
                self.prefetch_far_ball(ii, r, c2, m2);
            }
            let lv = lv | if compact { COMPLETE } else { 0 };
            match (m1 != 0, m2 != 0) {
                (true, true) => {
                    if !self.params.ordered || hmin(e1, m1) <= hmin(e2, m2) {
                        stack.push((r as u32, c2, lv, m2, e2));
                        stack.push((l as u32, c1, lv, m1, e1));
                    } else {
                        stack.push((l as u32, c1, lv, m1, e1));
                        stack.push((r as u32, c2, lv, m2, e2));
                    }
                }
                (true, false) => stack.push((l as u32, c1, lv, m1, e1)),
                (false, true) => stack.push((r as u32, c2, lv, m2, e2)),
                (false, false) => {}
            }
        }
    }

    /// Any-hit for up to eight rays (lanes of `active`), traversed together as in
    /// [`intersect_x8`](Self::intersect_x8), with [`occluded_ex`](Self::occluded_ex)'s
    /// updated-child-first order; a ray leaves the packet at its first accepted hit. Returns
    /// the mask of occluded rays (equal to `occluded_ex` ray by ray).
    pub fn occluded_x8(&self, rays: &[Ray], active: u8, ctr: &mut Counters, dc: &mut DeformCounters) -> u8 {
        assert!(rays.len() <= 8, "a packet holds at most 8 rays");
        let active = active & if rays.len() == 8 { 0xff } else { (1u8 << rays.len()) - 1 };
        if self.mode == UpdateMode::Refit || self.frame == 0 {
            let mut m = 0u8;
            for i in lanes(active) {
                if self.occluded_ex(&rays[i], ctr, dc) {
                    m |= 1 << i;
                }
            }
            return m;
        }
        let valid = valid_mask(rays) & active;
        if valid == 0 {
            return 0;
        }
        let pk = packet(rays, valid);
        let tfar = f32x8::from(std::array::from_fn::<f32, 8, _>(|i| if valid & (1 << i) != 0 { rays[i].tfar } else { f32::NEG_INFINITY }));
        let w0 = dc.sphere_tests + dc.leaf_tests;
        let mut sc = take_scratch();
        self.root_hits_x8(&pk, valid, tfar, dc, ctr, &mut sc.roots);
        own_last(&mut sc.roots, pk.tnear());
        let entered = sc.roots.iter().fold(0u8, |a, r| a | r.2);
        let stack = &mut sc.any;
        let done = self.occluded_roots_x8(rays, &pk, valid, tfar, &sc.roots, stack, dc, ctr);
        PACKET_SCRATCH.set(sc);
        dc.shadow_rays += valid.count_ones() as u64;
        dc.shadow_entered += entered.count_ones() as u64;
        dc.shadow_occluded += done.count_ones() as u64;
        dc.shadow_tests += dc.sphere_tests + dc.leaf_tests - w0;
        done
    }

    /// The traversal of [`occluded_x8`](Self::occluded_x8) below the instances `roots` hit.
    #[allow(clippy::too_many_arguments)]
    fn occluded_roots_x8(
        &self,
        rays: &[Ray],
        pk: &RayPacketX8,
        valid: u8,
        tfar: f32x8,
        roots: &[(f32, usize, u8, f32x8)],
        stack: &mut Vec<(u32, u32, u8, u8)>,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
    ) -> u8 {
        let mut done = 0u8;
        for &(_, k, m, _) in roots {
            let m = m & !done;
            if m == 0 {
                continue;
            }
            // One copy of the loop per kind of tree, so no node checks `ii.naive` again.
            // (A const parameter rather than `nv` alone: each copy then has its own `expand`
            // closure, inlined at its one call site.)
            let ii = &self.inst[k];
            done = match &ii.naive {
                Some(t) => self.occluded_in_x8::<true>(k, t, rays, pk, valid, tfar, m, done, stack, dc, ctr),
                None => self.occluded_in_x8::<false>(k, &ii.obj.tree.topo, rays, pk, valid, tfar, m, done, stack, dc, ctr),
            };
            if done == valid {
                return done;
            }
        }
        done
    }

    /// [`occluded_roots_x8`](Self::occluded_roots_x8) below the root of instance k (`topo`
    /// its tree, its naive one if `NAIVE`) for the lanes `m`: returns `done` with the lanes
    /// occluded there.
    #[allow(clippy::too_many_arguments)]
    #[inline(always)]
    fn occluded_in_x8<const NAIVE: bool>(
        &self,
        k: usize,
        topo: &Topology,
        rays: &[Ray],
        pk: &RayPacketX8,
        valid: u8,
        tfar: f32x8,
        m: u8,
        mut done: u8,
        stack: &mut Vec<(u32, u32, u8, u8)>,
        dc: &mut DeformCounters,
        ctr: &mut Counters,
    ) -> u8 {
        let ii = &self.inst[k];
        let nv = if NAIVE { Some(topo) } else { None };
        if topo.right[0] == LEAF {
            return done | self.leaf_x8(k, 0, rays, pk, m, tfar, dc, ctr);
        }
        // Stack entries are (node, count, level | UNTESTED, lanes): a node whose sphere was
        // tested already, together with its sibling, when both were current (one load of
        // each and two independent tests, so the two misses overlap), or one still to test
        // (the paper's shadow-ray order: the current child first, and the other updated
        // only if the ray still needs it, §4.4).
        // The count (n's kind and children, [`Topology::split`]) rides on the stack
        // rather than costing a load per node.
        // COMPLETE in the level byte as in `closest_in_x8` (only on tested entries: both
        // children of a complete node are current, so they are tested together).
        const UNTESTED: u8 = 0x80;
        let expand = |stack: &mut Vec<(u32, u32, u8, u8)>, n: usize, c: u32, lv: u8, m: u8, dc: &mut DeformCounters, ctr: &mut Counters| {
            let (l, (r, nl, nr)) = (n + 1, Topology::split(n, c));
            let (leaf_l, leaf_r) = (nl == 1, nr == 1);
            let known = lv & COMPLETE != 0;
            // Levels past LEVELS − 1 share the counters' last level anyway.
            let lv = (lv & !COMPLETE).min(LEVELS as u8 - 2);
            // Each child's sphere if it is current (one stamp check and load each), both
            // from the compact balls in a complete subtree (n is current: it was tested).
            let (sl, sr, compact) = match self.compact_children(ii, nv, n, c, r, known) {
                Some((a, b)) => (Some(a), Some(b), true),
                None => {
                    self.prefetch_node(ii, nv, r, leaf_r);
                    let sl = self.current_sphere(ii, nv, l, leaf_l);
                    let sr = if sl.is_some() || self.params.shadow_updated_first { self.current_sphere(ii, nv, r, leaf_r) } else { None };
                    (sl, sr, false)
                }
            };
            if let (Some((cl, rl)), Some((cr, rr))) = (sl, sr) {
                let cnt = 2 * m.count_ones() as u64;
                dc.sphere_tests += cnt;
                dc.tests_below(lv + 1, cnt);
                ctr.add(Counter::node_tests, cnt);
                let (ml, mr) = (m & pk.test_any(cl, rl, tfar), m & pk.test_any(cr, rr, tfar));
                if leaf_l && ml != 0 {
                    self.prefetch_leaf(ii, topo, l);
                }
                if leaf_r && mr != 0 {
                    self.prefetch_leaf(ii, topo, r);
                }
                let kc = if compact {
                    // As in `closest_in_x8`: the far grandchild balls a level ahead.
                    self.prefetch_far_ball(ii, l, nl, ml);
                    self.prefetch_far_ball(ii, r, nr, mr);
                    COMPLETE
                } else {
                    0
                };
                if mr != 0 {
                    stack.push((r as u32, nr, (lv + 1) | kc, mr));
                }
                if ml != 0 {
                    stack.push((l as u32, nl, (lv + 1) | kc, ml));
                }
            } else if !self.params.shadow_updated_first || sl.is_some() || sr.is_none() {
                // §4.4: the current child first (`left_first`).
                stack.push((r as u32, nr, (lv + 1) | UNTESTED, m));
                stack.push((l as u32, nl, (lv + 1) | UNTESTED, m));
            } else {
                stack.push((l as u32, nl, (lv + 1) | UNTESTED, m));
                stack.push((r as u32, nr, (lv + 1) | UNTESTED, m));
            }
        };
        // The root (tested in `root_hits_x8`) as a tested entry, so `expand` has one call
        // site and is inlined into the loop.
        stack.clear();
        stack.push((0, topo.count[0], 0, m));
        while let Some((n, c, lv, m)) = stack.pop() {
            let mut m = m & !done;
            if m == 0 {
                continue;
            }
            let n = n as usize;
            let (untested, leaf, lv) = (lv & UNTESTED != 0, c == 1, lv & !UNTESTED);
            if untested {
                let (c, r) = self.sphere_as_nv(ii, nv, n, leaf);
                let cnt = m.count_ones() as u64;
                dc.sphere_tests += cnt;
                dc.tests_below(lv, cnt);
                ctr.add(Counter::node_tests, cnt);
                m &= pk.test_any(c, r, tfar);
                if m == 0 {
                    continue;
                }
            }
            if leaf {
                done |= self.leaf_x8(k, n, rays, pk, m, tfar, dc, ctr);
                if done == valid {
                    return done;
                }
            } else {
                expand(stack, n, c, lv, m, dc, ctr);
            }
        }
        done
    }

    /// Front-to-back traversal of the refitted BVH2s (closest hit into `best`, or with `any`
    /// the first accepted hit ends it; returns whether one was found).
    fn refit_traverse(&self, ray: &Ray, best: &mut Best, any: bool, dc: &mut DeformCounters, ctr: &mut Counters) -> bool {
        let slab = Slab::new(ray);
        let mut roots: Vec<(f32, usize)> = Vec::new();
        let mut cand = Vec::with_capacity(self.inst.len());
        let top_tests = self.top.candidates_1(ray, best.t, &mut cand);
        dc.sphere_tests += top_tests;
        ctr.add(Counter::node_tests, top_tests);
        for k in cand {
            let k = k as usize;
            let bvh = self.inst[k].refit.as_ref().expect("refit tree");
            dc.sphere_tests += 1;
            ctr.inc(Counter::node_tests);
            if let Some(te) = bvh.nodes.first().and_then(|n| slab.test(n.aabb(), best.t)) {
                roots.push((te, k));
            }
        }
        roots.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut stack: Vec<(u32, f32)> = Vec::with_capacity(64);
        for (te, k) in roots {
            if te > best.t {
                continue;
            }
            let bvh = self.inst[k].refit.as_ref().expect("refit tree");
            stack.clear();
            stack.push((0, te));
            while let Some((n, te)) = stack.pop() {
                if te > best.t {
                    continue;
                }
                let node = &bvh.nodes[n as usize];
                if node.is_leaf() {
                    let (a, b) = (node.first_index as usize, (node.first_index + node.prim_count) as usize);
                    for &s in &bvh.primitive_indices[a..b] {
                        if !any {
                            self.visit(k, s as usize, u32::MAX, ray, best, dc, ctr);
                        } else if self.leaf_surfel(k, s as usize, u32::MAX, ray, dc, ctr).is_some() {
                            return true;
                        }
                    }
                    continue;
                }
                let (l, r) = (node.first_index, node.first_index + 1);
                dc.sphere_tests += 2;
                ctr.add(Counter::node_tests, 2);
                let e1 = slab.test(bvh.nodes[l as usize].aabb(), best.t);
                let e2 = slab.test(bvh.nodes[r as usize].aabb(), best.t);
                match (e1, e2) {
                    (Some(a), Some(b)) => {
                        if a <= b {
                            stack.push((r, b));
                            stack.push((l, a));
                        } else {
                            stack.push((l, a));
                            stack.push((r, b));
                        }
                    }
                    (Some(a), None) => stack.push((l, a)),
                    (None, Some(b)) => stack.push((r, b)),
                    (None, None) => {}
                }
            }
        }
        best.hit.is_some()
    }

    /// Updates every node of the lazy hierarchies (Eq. 9 in parallel, then Eq. 11 bottom-up)
    /// and deforms every surfel: a full refit. For checks, statistics and refit comparisons;
    /// a no-op for naive trees (rebuilt in `begin_frame`).
    pub fn update_all(&self) {
        for ii in &self.inst {
            if ii.naive.is_some() || ii.refit.is_some() {
                continue;
            }
            (0..ii.obj.surfel_count()).into_par_iter().for_each(|s| {
                self.surfel(ii, s);
            });
            let topo = &ii.obj.tree.topo;
            (0..topo.len()).into_par_iter().for_each(|n| {
                if topo.right[n] != LEAF {
                    self.sphere(ii, n);
                }
            });
            if self.params.eq11 {
                for n in (0..topo.len()).rev() {
                    if topo.right[n] != LEAF {
                        let s1 = self.sphere(ii, n + 1);
                        let s2 = self.sphere(ii, topo.right[n] as usize);
                        let (c, _) = self.sphere(ii, n);
                        self.tighten(ii, n, c, s1, s2);
                    }
                }
            }
        }
    }

    // -- statistics and checks -------------------------------------------------------------

    /// Update statistics of the current frame (count of stamped nodes and surfels).
    pub fn frame_stats(&self) -> FrameStats {
        let mode = match self.mode {
            UpdateMode::Auto if self.auto.naive => "auto/naive".to_string(),
            UpdateMode::Auto => "auto/lazy".to_string(),
            m => m.name().to_string(),
        };
        let mut fs = FrameStats { frame: self.frame, mode, update_seconds: self.update_seconds, ..Default::default() };
        for ii in &self.inst {
            let topo = &ii.obj.tree.topo;
            let inner = topo.right.iter().filter(|r| **r != LEAF).count() as u64;
            fs.inner_nodes_total += inner;
            fs.surfels_total += ii.obj.surfel_count() as u64;
            fs.surfels_deformed += ii.surf.slot.iter().filter(|s| s.stamp.load(Relaxed) == self.frame).count() as u64;
            if let Some(b) = &ii.refit {
                // The refitted tree replaces the sphere tree in the totals: all its nodes move.
                let bi = b.nodes.iter().filter(|n| !n.is_leaf()).count() as u64;
                fs.inner_nodes_total = fs.inner_nodes_total - inner + bi;
                fs.inner_nodes_updated += bi;
            } else if ii.naive.is_some() {
                fs.inner_nodes_updated += inner;
            } else {
                fs.inner_nodes_updated +=
                    (0..topo.len()).filter(|&n| topo.right[n] != LEAF && ii.nodes.slot[n].stamp.load(Relaxed) == self.frame).count() as u64;
                fs.nodes_tightened += ii.nodes.slot.iter().filter(|s| s.tight.load(Relaxed) == self.frame).count() as u64;
            }
        }
        fs
    }

    /// The deformed state of surfel `s` of instance `k` in this frame (pure; does not touch
    /// the lazy state). For previews and checks.
    pub fn deformed_surfel(&self, k: usize, s: usize) -> DeformedSurfel {
        deform_surfel(&self.inst[k].obj, &self.inst[k].field, s)
    }

    /// Inner nodes that are current this frame, as (instance, node, level).
    fn current_inner(&self) -> Vec<(usize, usize, u8)> {
        let mut v = Vec::new();
        for (k, ii) in self.inst.iter().enumerate().filter(|(_, ii)| ii.refit.is_none()) {
            let topo = self.topo(ii);
            for n in 0..topo.len() {
                if topo.right[n] != LEAF && (ii.naive.is_some() || ii.nodes.slot[n].stamp.load(Relaxed) == self.frame) {
                    v.push((k, n, topo.level[n]));
                }
            }
        }
        v
    }

    /// The sphere a node has now (without updating).
    fn sphere_now(&self, ii: &Instance, n: usize) -> (Vec3, f32) {
        match &ii.naive {
            Some(t) => (t.center(n), t.r[n]),
            // A leaf's sphere is its surfel's ball (`sphere`).
            None => match leaf_surfel(ii, n) {
                Some(s) => load_surfel_ball(&ii.surf, s),
                None => ii.nodes.load(n),
            },
        }
    }

    /// Radius ratio per level over the inner nodes updated this frame, at most
    /// `max_per_level` nodes sampled per level (evenly by index; deterministic).
    pub fn radius_ratios(&self, max_per_level: usize) -> Vec<LevelRatio> {
        let cur = self.current_inner();
        let depth = cur.iter().map(|c| c.2 as usize + 1).max().unwrap_or(0);
        let mut out = Vec::new();
        for lv in 0..depth {
            let at: Vec<&(usize, usize, u8)> = cur.iter().filter(|c| c.2 as usize == lv).collect();
            if at.is_empty() {
                continue;
            }
            let step = at.len().div_ceil(max_per_level.max(1));
            let sample: Vec<&(usize, usize, u8)> = at.iter().step_by(step).copied().collect();
            let ratios: Vec<f64> = sample
                .par_iter()
                .map(|&&(k, n, _)| {
                    let ii = &self.inst[k];
                    let topo = self.topo(ii);
                    let (st, ct) = (topo.start[n] as usize, topo.count[n] as usize);
                    let def: Vec<DeformedSurfel> =
                        topo.perm[st..st + ct].iter().map(|&s| deform_surfel(&ii.obj, &ii.field, s as usize)).collect();
                    let pts: Vec<Vec3> = def.iter().map(|d| d.p).collect();
                    let (c, _) = miniball(&pts);
                    let tight = def.iter().map(|d| (d.p - c).length() + d.extent()).fold(0.0f32, f32::max);
                    self.sphere_now(ii, n).1 as f64 / tight.max(1e-30) as f64
                })
                .collect();
            out.push(LevelRatio {
                level: lv as u32,
                nodes_updated: at.len() as u64,
                sampled: ratios.len() as u64,
                mean_ratio: ratios.iter().sum::<f64>() / ratios.len() as f64,
                max_ratio: ratios.iter().copied().fold(0.0, f64::max),
            });
        }
        out
    }

    /// Checks that every current node's sphere holds the deformed ellipses of all surfels of
    /// its subtree (and every leaf its surfel); for `Refit`, that every box holds its
    /// children's boxes and every leaf box its surfels' balls. Returns a violation on failure.
    pub fn check_containment(&self) -> Result<(), String> {
        for (k, ii) in self.inst.iter().enumerate() {
            let Some(b) = &ii.refit else { continue };
            let inside = |o: &Aabb, i: &Aabb| o.min.cmple(i.min).all() && i.max.cmple(o.max).all();
            for (n, node) in b.nodes.iter().enumerate() {
                if node.is_leaf() {
                    let (a, e) = (node.first_index as usize, (node.first_index + node.prim_count) as usize);
                    for &s in &b.primitive_indices[a..e] {
                        let d = deform_surfel(&ii.obj, &ii.field, s as usize);
                        let (c, r) = leaf_sphere(&d);
                        let ball = Aabb::new(Vec3A::from(c - Vec3::splat(r)), Vec3A::from(c + Vec3::splat(r)));
                        if !inside(node.aabb(), &ball) {
                            return Err(format!("instance {k} refit leaf {n}: surfel {s} outside its box"));
                        }
                    }
                } else {
                    for ch in [node.first_index, node.first_index + 1] {
                        if !inside(node.aabb(), b.nodes[ch as usize].aabb()) {
                            return Err(format!("instance {k} refit node {n}: child {ch} outside its box"));
                        }
                    }
                }
            }
        }
        let cur = self.current_inner();
        let bad: Option<String> = cur
            .par_iter()
            .filter_map(|&(k, n, _)| {
                let ii = &self.inst[k];
                let topo = self.topo(ii);
                // The first surfel of node q's subtree that pokes out of (c, r), and how far.
                let outside = |q: usize, (c, r): (Vec3, f32)| {
                    let (st, ct) = (topo.start[q] as usize, topo.count[q] as usize);
                    topo.perm[st..st + ct].iter().find_map(|&s| {
                        let d = deform_surfel(&ii.obj, &ii.field, s as usize);
                        let reach = (d.p - c).length() + d.extent();
                        (!(reach <= r)).then_some((s, reach, r))
                    })
                };
                if let Some((s, reach, r)) = outside(n, self.sphere_now(ii, n)) {
                    return Some(format!("instance {k} node {n} (level {}): surfel {s} reaches {reach}, radius {r}", topo.level[n]));
                }
                // The compact balls that traversals would read below n instead of slots: every
                // ball of a complete subtree is a child of one of its current inner nodes.
                let rc = topo.right_child(n);
                let (b1, b2) = self.compact_children(ii, ii.naive.as_ref(), n, topo.count[n], rc, false)?;
                [(n + 1, b1), (rc, b2)].into_iter().find_map(|(q, b)| {
                    outside(q, b)
                        .map(|(s, reach, r)| format!("instance {k} ball {q} (below complete {n}): surfel {s} reaches {reach}, radius {r}"))
                })
            })
            .min();
        match bad {
            Some(b) => Err(b),
            None => Ok(()),
        }
    }
}

/// The surfel of node `n` of the lazy (rest-pose) tree if n is a leaf. The lazy modes keep a
/// leaf's sphere in its surfel's slot, not in the node slots (`DeformTracer::sphere`).
#[inline(always)]
fn leaf_surfel(ii: &Instance, n: usize) -> Option<usize> {
    let topo = &ii.obj.tree.topo;
    (topo.right[n] == LEAF).then(|| topo.surfel[n] as usize)
}

/// The node a hit at leaf `n` reports (for the per-ray cache): none in a rebuilt tree.
#[inline]
fn leaf_node(ii: &Instance, n: usize) -> u32 {
    leaf_node_of(ii.naive.is_some(), n)
}

/// [`leaf_node`] for a traversal that knows whether it walks a naive (rebuilt) tree.
#[inline(always)]
fn leaf_node_of(naive: bool, n: usize) -> u32 {
    if naive {
        u32::MAX
    } else {
        n as u32
    }
}

/// Whether surfel `s` belongs to a collection with clipping partners (§4.3).
#[inline]
fn clipped_surfel(ii: &Instance, s: usize) -> bool {
    ii.clipped && !ii.obj.clip_partners[ii.obj.coll[s] as usize].is_empty()
}

/// The smallest sphere holding the spheres `a` and `b`, padded like the other radii.
#[inline]
pub(super) fn enclosing_sphere(a: (Vec3, f32), b: (Vec3, f32)) -> (Vec3, f32) {
    let ((c1, r1), (c2, r2)) = (a, b);
    let d = (c2 - c1).length();
    let (c, r) = if d + r2 <= r1 {
        (c1, r1)
    } else if d + r1 <= r2 {
        (c2, r2)
    } else {
        let r = 0.5 * (d + r1 + r2);
        (c1 + (c2 - c1) * ((r - r1) / d), r)
    };
    (c, r * (1.0 + RADIUS_PAD) + RADIUS_PAD * c.abs().max_element())
}

/// Lanes (bit indices) set in `m`, lowest first.
#[inline]
fn lanes(m: u8) -> impl Iterator<Item = usize> {
    let mut m = m;
    std::iter::from_fn(move || {
        if m == 0 {
            None
        } else {
            let i = m.trailing_zeros() as usize;
            m &= m - 1;
            Some(i)
        }
    })
}

/// Bit i set when `rays[i]` is valid.
#[inline]
fn valid_mask(rays: &[Ray]) -> u8 {
    rays.iter().enumerate().fold(0u8, |m, (i, r)| if traceable(r) { m | 1 << i } else { m })
}

/// Whether the tracer takes `ray` at all (every entry point, [`DeformTracer::closest_brute`]
/// included, so the hits still equal the brute-force search's): a valid ray
/// ([`Ray::is_valid`]) whose direction's squared length lies in [1e-24, 1e24]. Directions are
/// not normalised, and beyond that range the sphere kernels' squares underflow or overflow
/// (a direction of length 1e-20 culled every node past the first hit; review finding,
/// stop 49).
#[inline]
fn traceable(ray: &Ray) -> bool {
    ray.is_valid() && (1e-24..=1e24).contains(&ray.dir.length_squared())
}

/// The rays of `valid` as a packet; other lanes get a harmless dummy ray (they are masked).
#[inline]
fn packet(rays: &[Ray], valid: u8) -> RayPacketX8 {
    let (mut o, mut d, mut tn) = ([[0f32; 8]; 3], [[0f32; 8]; 3], [0f32; 8]);
    for i in 0..8 {
        let (org, dir, tnear) = if valid & (1 << i) != 0 { (rays[i].org, rays[i].dir, rays[i].tnear) } else { (Vec3::ZERO, Vec3::X, 0.0) };
        for a in 0..3 {
            o[a][i] = org[a];
            d[a][i] = dir[a];
        }
        tn[i] = tnear;
    }
    RayPacketX8::new(&o, &d, &tn)
}

/// Each lane's current closest distance.
#[inline]
fn best_t(best: &[Best; 8]) -> f32x8 {
    f32x8::from(std::array::from_fn::<f32, 8, _>(|i| best[i].t))
}

/// The any-hit traversals' order of the instances along a packet (`roots`, nearest entry
/// first, from `root_hits_x8`): each lane searches the instances whose root sphere holds its
/// origin last. Any hit ends a shadow ray, so the order is free and the result the same. A
/// shadow ray leaving a surface starts inside its own object's root, which it rarely hits
/// again, and its descent there is costly (it starts inside every sphere on the way to its
/// surfel, and meets the overlapping splats beside it: about 8 % of an `elastic-balls`
/// frame, stop 71); a ray that another object blocks now ends before that descent. Not in
/// the paper (§4.4 orders the children within one hierarchy). The lanes that start inside an
/// instance move to a second entry for it at the end; `occluded_roots_x8` skips the empty
/// ones.
fn own_last(roots: &mut Vec<(f32, usize, u8, f32x8)>, tnear: f32x8) {
    for i in 0..roots.len() {
        let (t, k, m, e) = roots[i];
        let inside = m & e.simd_le(tnear).to_bitmask() as u8;
        if inside != 0 {
            roots[i].2 = m & !inside;
            roots.push((t, k, inside, e));
        }
    }
}

/// Smallest entry over the lanes of `m` (m ≠ 0).
#[inline]
fn hmin(e: f32x8, m: u8) -> f32 {
    // Branch-free: the lanes outside m set to +∞, then a min over all eight (no lane of m
    // is NaN: the sphere tests report a lane only when its entry compared ≤ tfar).
    const BIT: [u32; 8] = [1, 2, 4, 8, 16, 32, 64, 128];
    let bit = u32x8::from(BIT);
    let sel: f32x8 = wide::bytemuck::cast((u32x8::splat(m as u32) & bit).simd_eq(bit));
    let v = sel.bitselect(e, f32x8::splat(f32::INFINITY)).to_array();
    let h = [v[0].min(v[4]), v[1].min(v[5]), v[2].min(v[6]), v[3].min(v[7])];
    h[0].min(h[2]).min(h[1].min(h[3]))
}

/// How far ahead [`DeformTracer::refit_subtree`] prefetches the surfel and node slots it
/// will write (in elements).
const PREFETCH_AHEAD: usize = 8;

/// Asks for the cache line of `x` ahead of a read of it (a hint; no effect elsewhere than
/// x86-64).
#[inline(always)]
fn prefetch_read<T>(x: &T) {
    prefetch_hint::<false, T>(x)
}

/// Asks for the cache line of `s[i]` ahead of a write to it (a hint, as [`prefetch_read`]),
/// without a bounds check: a prefetch of any address is harmless, and each check was a
/// compare and a branch on the traversals' paths.
#[inline(always)]
fn prefetch_at<T>(s: &[T], i: usize) {
    prefetch_hint::<true, T>(s.as_ptr().wrapping_add(i))
}

/// [`prefetch_read`] of `s[i]`, without a bounds check (as [`prefetch_at`]).
#[inline(always)]
fn prefetch_read_at<T>(s: &[T], i: usize) {
    prefetch_hint::<false, T>(s.as_ptr().wrapping_add(i))
}

#[inline(always)]
fn prefetch_hint<const WRITE: bool, T>(x: *const T) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_mm_prefetch, _MM_HINT_ET0, _MM_HINT_T0};
        let p = x as *const i8;
        // SAFETY: a prefetch is a hint and never faults, whatever the address.
        unsafe {
            if WRITE {
                _mm_prefetch::<_MM_HINT_ET0>(p)
            } else {
                _mm_prefetch::<_MM_HINT_T0>(p)
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = x;
}

/// Starts the loads of Eq. 1's per-surfel inputs of surfel `s` (reference position and
/// axes, node indices and weights; [`deform_surfel`]). A subtree refit deforms its surfels
/// in leaf order, and perf put two thirds of `deform_surfel`'s samples on the first use of
/// these four arrays (stop 67): each is a miss, and the loop's other work hid none of them.
#[inline(always)]
fn prefetch_surfel_inputs(obj: &SurfelObject, s: usize) {
    let k = obj.weights.k;
    prefetch_read_at(&obj.pos, s);
    prefetch_read_at(&obj.axes, s);
    if k == 0 {
        return;
    }
    // A row of k = 16 entries is one line's worth but rarely line-aligned: ask for both ends.
    prefetch_read_at(&obj.weights.idx, s * k);
    prefetch_read_at(&obj.weights.idx, s * k + k - 1);
    prefetch_read_at(&obj.weights.w, s * k);
    prefetch_read_at(&obj.weights.w, s * k + k - 1);
}

#[inline]
fn deform_surfel(obj: &SurfelObject, f: &DeformField, s: usize) -> DeformedSurfel {
    let k = obj.weights.k;
    deform_point(f, obj.pos[s], obj.axes[s], &obj.weights.idx[s * k..s * k + k], &obj.weights.w[s * k..s * k + k])
}

#[inline]
/// Stores the deformed surfel `d` as this frame's; returns the unit normal and leaf-ball
/// radius it stored with it.
fn store_surfel(st: &SurfelState, s: usize, d: &DeformedSurfel, frame: u32) -> (Vec3, f32) {
    let (n, r) = (d.normal(), leaf_sphere(d).1);
    store_surfel_nr(st, s, d, n, r, frame);
    (n, r)
}

/// [`store_surfel`] with the unit normal `n` and leaf-ball radius `r` already computed
/// ([`normal_extent_x8`]).
#[inline]
fn store_surfel_nr(st: &SurfelState, s: usize, d: &DeformedSurfel, n: Vec3, r: f32, frame: u32) {
    let v = [d.p.x, d.p.y, d.p.z, d.u.x, d.u.y, d.u.z, d.v.x, d.v.y, d.v.z, d.stretch, n.x, n.y, n.z, r];
    let slot = &st.slot[s];
    for (a, x) in slot.d.iter().zip(v) {
        a.store(x.to_bits(), Relaxed);
    }
    slot.stamp.store(frame, Release);
}

/// [`DeformedSurfel::normal`] and [`DeformedSurfel::extent`] of up to eight surfels in one
/// f32x8 pass, bit for bit (the same IEEE operations in the same order: a surfel stored by
/// [`store_surfel`] in one mode and through this in another gives the same images). Lanes
/// past `d.len()` are left zero. Scalar, each surfel is a chain of three dependent square
/// roots and a division after its Eq. 1 sum, which the whole-object refits of
/// `elastic-balls` waited on surfel after surfel (perf: `store_surfel` took as long as
/// `deform_surfel`).
fn normal_extent_x8(d: &[DeformedSurfel]) -> ([Vec3; 8], [f32; 8]) {
    debug_assert!(d.len() <= 8);
    let col = |f: fn(&DeformedSurfel) -> f32| f32x8::from(std::array::from_fn::<f32, 8, _>(|i| d.get(i).map_or(0.0, f)));
    let (ux, uy, uz) = (col(|s| s.u.x), col(|s| s.u.y), col(|s| s.u.z));
    let (vx, vy, vz) = (col(|s| s.v.x), col(|s| s.v.y), col(|s| s.v.z));
    // glam's `cross`, `dot` and `normalize_or_zero`, in their order.
    let (nx, ny, nz) = (uy * vz - vy * uz, uz * vx - vz * ux, ux * vy - vx * uy);
    let rcp = f32x8::ONE / (nx * nx + ny * ny + nz * nz).sqrt();
    let ok = rcp.simd_lt(f32x8::splat(f32::INFINITY)) & rcp.simd_gt(f32x8::ZERO);
    let (nx, ny, nz) = (ok.bitselect(nx * rcp, f32x8::ZERO), ok.bitselect(ny * rcp, f32x8::ZERO), ok.bitselect(nz * rcp, f32x8::ZERO));
    // `extent`: the largest singular value of [u v].
    let a = ux * ux + uy * uy + uz * uz;
    let b = ux * vx + uy * vy + uz * vz;
    let c = vx * vx + vy * vy + vz * vz;
    let l = f32x8::splat(0.5) * (a + c + ((a - c) * (a - c) + f32x8::splat(4.0) * b * b).sqrt());
    let e = l.max(f32x8::ZERO).sqrt().to_array();
    let (nx, ny, nz) = (nx.to_array(), ny.to_array(), nz.to_array());
    (std::array::from_fn(|i| Vec3::new(nx[i], ny[i], nz[i])), e)
}

#[inline]
fn load_surfel(st: &SurfelState, s: usize) -> DeformedSurfel {
    let d = &st.slot[s].d;
    let g = |k: usize| f32::from_bits(d[k].load(Relaxed));
    DeformedSurfel { p: Vec3::new(g(0), g(1), g(2)), u: Vec3::new(g(3), g(4), g(5)), v: Vec3::new(g(6), g(7), g(8)), stretch: g(9) }
}

/// Leaf ball (centre, padded extent) of a stored surfel.
#[inline]
fn load_surfel_ball(st: &SurfelState, s: usize) -> (Vec3, f32) {
    let d = &st.slot[s].d;
    let g = |k: usize| f32::from_bits(d[k].load(Relaxed));
    (Vec3::new(g(0), g(1), g(2)), g(13))
}

/// Position and unit normal of a stored surfel.
#[inline]
fn load_surfel_pn(st: &SurfelState, s: usize) -> (Vec3, Vec3) {
    let d = &st.slot[s].d;
    let g = |k: usize| f32::from_bits(d[k].load(Relaxed));
    (Vec3::new(g(0), g(1), g(2)), Vec3::new(g(10), g(11), g(12)))
}

/// The box of a surfel's leaf ball, padded against rounding like the sphere tests.
#[inline]
fn ball_box(d: &DeformedSurfel) -> Aabb {
    let (c, r) = leaf_sphere(d);
    let pad = Vec3::splat(r * 1e-5 + 1e-6 * c.abs().max_element());
    let e = Vec3A::from(Vec3::splat(r) + pad);
    Aabb::new(Vec3A::from(c) - e, Vec3A::from(c) + e)
}

/// The refit baseline's BVH2 over the undeformed surfels (`UpdateMode::Refit`).
fn refit_build(obj: &SurfelObject) -> Bvh2 {
    let f = DeformField::identity(&obj.nodes);
    let boxes: Vec<Aabb> = (0..obj.surfel_count()).into_par_iter().map(|s| ball_box(&deform_surfel(obj, &f, s))).collect();
    let mut t = std::time::Duration::default();
    obvhs::bvh2::builder::build_bvh2(&boxes, obvhs::BvhBuildParams::medium_build(), &mut t)
}

/// Ray–box slab test for the refit baseline (t in multiples of the ray direction), widened
/// by a relative 4 ulp so rounding never reports a miss for a box the ray meets.
struct Slab {
    o: Vec3,
    inv: Vec3,
    tnear: f32,
}

impl Slab {
    fn new(ray: &Ray) -> Self {
        Slab { o: ray.org, inv: ray.dir.recip(), tnear: ray.tnear }
    }
    /// Entry parameter (≥ tnear) if the box overlaps [tnear, tfar].
    #[inline]
    fn test(&self, b: &Aabb, tfar: f32) -> Option<f32> {
        let t0 = (Vec3::from(b.min) - self.o) * self.inv;
        let t1 = (Vec3::from(b.max) - self.o) * self.inv;
        // NaN (0·∞ for a ray in a slab's plane) is dropped by min/max: the slab is unbounded.
        let lo = t0.min(t1).max_element().max(self.tnear);
        let hi = t0.max(t1).min_element() * (1.0 + 4.0 * f32::EPSILON);
        (lo <= hi && lo <= tfar && lo < f32::INFINITY).then_some(lo)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `own_last` keeps every (instance, lane) pair exactly once, and puts each lane's
    /// instances that hold its origin (entry at tnear) after all the others, in their order.
    #[test]
    fn own_last_moves_the_lanes_inside_an_instance_behind_the_others() {
        let tn = f32x8::from([0.5, 0.5, 0.5, 0.5, 0.0, 0.0, 0.0, 0.0]);
        let e = |v: [f32; 8]| f32x8::from(v);
        // Instance 3 holds lanes 0-1 (entry = tnear) and is met by 2-3 from outside;
        // instance 7 holds lane 4; instance 9 is entered from outside by all it meets.
        let mut roots = vec![
            (0.5, 3, 0b0000_1111, e([0.5, 0.5, 0.9, 1.0, 9.0, 9.0, 9.0, 9.0])),
            (0.0, 7, 0b0001_0001, e([2.0, 9.0, 9.0, 9.0, 0.0, 9.0, 9.0, 9.0])),
            (1.5, 9, 0b1111_1111, e([1.5, 1.6, 1.7, 1.8, 1.9, 2.0, 2.1, 2.2])),
        ];
        let before = roots.clone();
        own_last(&mut roots, tn);
        let pairs = |r: &[(f32, usize, u8, f32x8)]| {
            let mut v: Vec<(usize, usize)> = r.iter().flat_map(|&(_, k, m, _)| lanes(m).map(move |i| (k, i))).collect();
            v.sort();
            v
        };
        assert_eq!(pairs(&roots), pairs(&before));
        let order: Vec<(usize, u8)> = roots.iter().filter(|r| r.2 != 0).map(|r| (r.1, r.2)).collect();
        assert_eq!(order, vec![(3, 0b0000_1100), (7, 0b0000_0001), (9, 0b1111_1111), (3, 0b0000_0011), (7, 0b0001_0000)]);
    }

    /// The f32x8 normals and extents (`normal_extent_x8`, the refits' and naive's path) equal
    /// the scalar ones (`DeformedSurfel::normal`, `extent`: the rays' lazy path) bit for bit,
    /// on random surfels and degenerate ones (collapsed, colinear, zero, huge, NaN axes), for
    /// every batch length; the lanes past the batch stay zero.
    #[test]
    fn normal_extent_x8_matches_scalar_bit_for_bit() {
        use crate::core::rng::Sampler;
        let mut g = Sampler::new(3, 1, 4);
        let mut v = |k: f32| Vec3::new(g.next() - 0.5, g.next() - 0.5, g.next() - 0.5) * k;
        let mut all = Vec::new();
        for i in 0..4000 {
            let (p, u) = (v(10.0), v(0.1));
            let w = match i % 8 {
                0 => u * 3.0,     // colinear
                1 => Vec3::ZERO,  // collapsed
                2 => u + v(1e-7), // near-colinear
                3 => v(1e18),     // huge (squares overflow)
                4 => Vec3::splat(f32::NAN),
                _ => v(0.1),
            };
            all.push(DeformedSurfel { p, u, v: w, stretch: 1.0 });
        }
        all.push(DeformedSurfel { p: Vec3::ZERO, u: Vec3::ZERO, v: Vec3::ZERO, stretch: 1.0 });
        let same = |a: f32, b: f32| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for len in 1..=8 {
            for d in all.chunks(len) {
                let (n, e) = normal_extent_x8(d);
                for (j, s) in d.iter().enumerate() {
                    let (ns, es) = (s.normal(), s.extent());
                    assert!(same(n[j].x, ns.x) && same(n[j].y, ns.y) && same(n[j].z, ns.z), "{s:?}: {} vs {ns}", n[j]);
                    assert!(same(e[j], es), "{s:?}: {} vs {es}", e[j]);
                }
                for j in d.len()..8 {
                    assert!(n[j] == Vec3::ZERO && e[j] == 0.0);
                }
            }
        }
    }

    /// Eq. 11 only ever shrinks a node's radius within a frame (the paper takes
    /// min(R', R'')): children whose enclosing sphere is larger than the node's current one,
    /// including one that passes the cheap pre-check (a child larger than the node, at its
    /// centre), leave the node as it is; a smaller enclosing sphere is taken.
    /// A unit ball of `n` surfels with simulation nodes inside it: (rest node positions,
    /// one-instance scene).
    fn ball_scene(n: usize) -> (Vec<Vec3>, DeformScene) {
        use super::super::object::ObjectParams;
        use super::super::sequences::nodes_inside;
        use super::super::surfel::{sphere_surfels, SurfelModel};
        let s = sphere_surfels(Vec3::ZERO, 1.0, n);
        let (nd, _) = nodes_inside(&|p: Vec3| p.length() <= 0.9, Vec3::splat(-1.0), Vec3::splat(1.0), 30);
        let m = vec![1.0; nd.len()];
        let obj = SurfelObject::build(SurfelModel::single("ball", s, [1.0; 3]), nd.clone(), m, &ObjectParams::default()).unwrap();
        (nd, DeformScene { objects: vec![obj], instances: vec![0] })
    }

    #[test]
    fn eq11_never_grows_a_radius() {
        let (_, scene) = ball_scene(400);
        let obj = scene.objects[0].clone();
        for recentre_eq11 in [true, false] {
            let mut tr = DeformTracer::new(&scene, UpdateMode::Lazy, TraceParams { recentre_eq11, ..TraceParams::default() }).unwrap();
            tr.begin_frame(std::slice::from_ref(&obj.nodes.rest)).unwrap();
            let ii = &tr.inst[0];
            let (c, r) = tr.sphere(ii, 0);
            // A child as large as 1.5 r at the node's centre: enclosing radius 1.5 r > r.
            tr.tighten(ii, 0, c, (c, 1.5 * r), (c, 0.0));
            assert_eq!(ii.nodes.load(0), (c, r), "recentre_eq11 {recentre_eq11}: the radius grew");
            // Two children far apart: larger too.
            tr.tighten(ii, 0, c, (c - Vec3::X * r, 0.5 * r), (c + Vec3::X * r, 0.5 * r));
            assert_eq!(ii.nodes.load(0), (c, r));
            // Two small children near the centre: taken.
            tr.tighten(ii, 0, c, (c - Vec3::X * 0.1 * r, 0.2 * r), (c + Vec3::X * 0.1 * r, 0.2 * r));
            let (_, r2) = ii.nodes.load(0);
            assert!(r2 < 0.5 * r, "recentre_eq11 {recentre_eq11}: {r2} against {r}");
        }
    }

    /// `refit_subtree`: the first visit of a node of ≤ `exact_below` surfels publishes its
    /// whole subtree, each sphere holding its leaf balls and no larger (within the padding)
    /// than the exact reach from their box centre (a node of two or three surfels: than the
    /// sphere around its two children); a subtree another thread has claimed in this frame
    /// is bounded by Eq. 9 instead, and either way every surfel stays inside.
    #[test]
    fn subtree_refit_is_exact_and_a_claimed_subtree_falls_back_to_eq9() {
        let (nd, scene) = ball_scene(600);
        // A bend: node positions moved smoothly, so the rest spheres no longer fit.
        let bent: Vec<Vec3> = nd.iter().map(|p| *p + Vec3::new(0.3 * p.y * p.y, 0.1 * p.x, 0.0)).collect();
        let mut tr = DeformTracer::new(&scene, UpdateMode::Lazy, TraceParams { exact_below: 256, ..TraceParams::default() }).unwrap();
        tr.begin_frame(std::slice::from_ref(&bent)).unwrap();
        let ii = &tr.inst[0];
        let topo = &ii.obj.tree.topo;
        let n = (0..topo.len()).find(|&q| topo.right[q] != LEAF && topo.count[q] > 100 && topo.count[q] <= 256).unwrap();
        let cnt = topo.count[n] as usize;
        tr.sphere(ii, n);
        for q in n..n + 2 * cnt - 1 {
            assert!(tr.current(ii, q), "node {q} of the subtree of {n} not published");
            let (c, r) = tr.sphere(ii, q);
            let (a, k) = (topo.start[q] as usize, topo.count[q] as usize);
            let balls: Vec<(Vec3, f32)> =
                topo.perm[a..a + k].iter().map(|&s| leaf_sphere(&deform_surfel(&ii.obj, &ii.field, s as usize))).collect();
            let reach_from = |c: Vec3| balls.iter().map(|(p, rr)| (*p - c).length() + rr).fold(0.0f32, f32::max);
            assert!(reach_from(c) <= r, "node {q}: a leaf ball reaches {} > {r}", reach_from(c));
            // No larger than the exact reach from the box centre; a node of two or three
            // surfels (`ENC_MAX`), than the sphere around its two children (Eq. 11,
            // re-centred).
            let (lo, hi) = balls.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), b| (lo.min(b.0), hi.max(b.0)));
            let best = if (2..=ENC_MAX).contains(&k) {
                enclosing_sphere(tr.sphere(ii, q + 1), tr.sphere(ii, topo.right[q] as usize)).1
            } else {
                reach_from(0.5 * (lo + hi))
            };
            assert!(r <= best * (1.0 + 1e-4) + 1e-6, "node {q}: radius {r}, the bound {best}");
        }
        let next = n + 2 * cnt - 1;
        assert!(next < topo.len() && !tr.current(ii, next), "the node after the subtree stays lazy");
        tr.check_containment().unwrap();
        // Next frame, with the subtree claimed by "another thread": Eq. 9 for n alone.
        tr.begin_frame(&[bent]).unwrap();
        let ii = &tr.inst[0];
        assert!(ii.nodes.slot[n].try_claim(tr.frame) && !ii.nodes.slot[n].try_claim(tr.frame));
        let (c, r) = tr.sphere(ii, n);
        let eq9 = ii.obj.tree.update_eq9(n, &ii.field, &ii.obj.nodes.rest, true, true);
        assert_eq!((c, r), eq9);
        assert!(!tr.current(ii, n + 1), "a claimed subtree's children are left to its owner");
        tr.check_containment().unwrap();
    }

    /// An object of at most 2·`exact_below` surfels is refitted whole when `begin_frame`
    /// makes its root current (the root exact, every node published); a larger one keeps an
    /// Eq. 9 root and leaves its subtrees lazy.
    #[test]
    fn a_small_object_is_refitted_whole_at_its_root() {
        let (nd, scene) = ball_scene(600);
        let bent: Vec<Vec3> = nd.iter().map(|p| *p + Vec3::new(0.3 * p.y * p.y, 0.1 * p.x, 0.0)).collect();
        for (exact_below, whole) in [(300, true), (299, false), (0, false)] {
            let mut tr = DeformTracer::new(&scene, UpdateMode::Lazy, TraceParams { exact_below, ..TraceParams::default() }).unwrap();
            tr.begin_frame(std::slice::from_ref(&bent)).unwrap();
            let ii = &tr.inst[0];
            let topo = &ii.obj.tree.topo;
            assert!(tr.current(ii, 0), "exact_below {exact_below}: the root is current after begin_frame");
            let all = (0..topo.len()).all(|q| tr.current(ii, q));
            assert_eq!(all, whole, "exact_below {exact_below}: every node published");
            let (c, r) = ii.nodes.load(0);
            let balls: Vec<(Vec3, f32)> = (0..ii.obj.surfel_count()).map(|s| leaf_sphere(&deform_surfel(&ii.obj, &ii.field, s))).collect();
            let reach = |c: Vec3| balls.iter().map(|(p, rr)| (*p - c).length() + rr).fold(0.0f32, f32::max);
            assert!(reach(c) <= r, "exact_below {exact_below}: a leaf ball leaves the root");
            let (lo, hi) = balls.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), b| (lo.min(b.0), hi.max(b.0)));
            let tight = r <= reach(0.5 * (lo + hi)) * (1.0 + 1e-4) + 1e-6;
            assert_eq!(tight, whole, "exact_below {exact_below}: root radius {r} against the exact reach {}", reach(0.5 * (lo + hi)));
            tr.check_containment().unwrap();
        }
    }

    /// `Auto` tries both modes, then keeps the cheaper one and probes the other after
    /// PROBE·r² frames; a change in cost flips it; without reports it stays lazy.
    #[test]
    fn auto_picks_the_cheaper_mode_and_probes_the_other() {
        let run = |costs: &dyn Fn(usize, bool) -> f64, n: usize| -> String {
            let mut a = AutoPick::default();
            (0..n)
                .map(|f| {
                    let naive = a.pick();
                    a.record(costs(f, naive));
                    if naive {
                        'N'
                    } else {
                        'l'
                    }
                })
                .collect()
        };
        // Lazy 2× cheaper: probe every 8·4 = 32 frames.
        let s = run(&|_, naive| if naive { 2.0 } else { 1.0 }, 70);
        assert_eq!(s, format!("Nl{}N{}N{}", "l".repeat(31), "l".repeat(31), "l".repeat(4)));
        // Naive 1.25× cheaper: probe lazy every 8·1.5625 = 12 frames.
        let s = run(&|_, naive| if naive { 1.0 } else { 1.25 }, 30);
        assert_eq!(&s[..16], "NlNNNNNNNNNNNlNN");
        // The costs cross at frame 20: the next probe of lazy flips the choice to it.
        let s = run(
            &|f, naive| {
                if naive {
                    1.0
                } else if f < 20 {
                    1.25
                } else {
                    0.5
                }
            },
            40,
        );
        let after = &s[s[20..].find('l').unwrap() + 20..];
        assert!(after.chars().filter(|&c| c == 'l').count() >= after.len() - 1, "{s}");
        // No reports (and non-finite ones): lazy after the first two frames, the rebuild
        // probed every PROBE frames.
        let mut a = AutoPick::default();
        let s: String = (0..20)
            .map(|_| {
                let n = a.pick();
                a.record(f64::NAN);
                if n {
                    'N'
                } else {
                    'l'
                }
            })
            .collect();
        assert_eq!(s, "NllllllllNlllllllNll");
    }

    /// A node's sphere is four words; a reader racing a writer that keeps moving it must
    /// still get one published sphere, never a centre mixed from two writes (the flaw of the
    /// protocol before stop 31). Each write k publishes c = (k, k, k), r = N − k: radii
    /// shrink as in a frame.
    #[test]
    fn racing_readers_see_only_published_spheres() {
        const N: u32 = 2_000_000;
        let st = NodeState::new(1);
        st.slot[0].write(Vec3::ZERO, N as f32);
        let done = std::sync::atomic::AtomicBool::new(false);
        std::thread::scope(|sc| {
            sc.spawn(|| {
                for k in 1..=N {
                    let s = &st.slot[0];
                    if s.try_lock() {
                        s.write(Vec3::splat(k as f32), (N - k) as f32);
                        s.unlock();
                    }
                }
                done.store(true, Relaxed);
            });
            let mut reads = 0u64;
            while !done.load(Relaxed) || reads < 1000 {
                let (c, r) = st.load(0);
                assert!(c.x == c.y && c.y == c.z, "centre mixed from two writes: {c}");
                assert_eq!(r, N as f32 - c.x, "radius of another write than the centre {c}");
                reads += 1;
            }
        });
    }

    /// The early clip (`TraceParams::clip_early`) rejects what the full clipping test would
    /// reject for every point the iteration can return, its start point included. That start
    /// point, the ray's ellipse hit x0, is not held to the leaf ball by `mls_intersect_x8`
    /// (only the points it moves to are): it lies in the ellipse up to the rounding of
    /// o + d·t, which from a far camera exceeds the early clip's 0.1 % margin on a small
    /// splat. Here x0 lies beside the ball, on the unclipped side of the partner's plane (1 cm
    /// beside a 4 cm ball, where rounding puts it a fraction of that; the logic is the same):
    /// the full test accepts the hit at x0, and so must the early one. Until the review of stop 80
    /// the early clip bounded only the leaf ball and rejected it.
    #[test]
    fn early_clip_bounds_the_start_point_too() {
        use super::super::object::ObjectParams;
        use super::super::sequences::nodes_inside;
        use super::super::surfel::{rect_surfels, SurfelModel};
        let sp = 0.05;
        let top = rect_surfels(Vec3::ZERO, Vec3::X, Vec3::Y, (-1.0, 0.3), (-0.5, 0.5), sp); // normal +z
        let side = rect_surfels(Vec3::ZERO, Vec3::Y, Vec3::Z, (-0.5, 0.5), (-1.0, 0.3), sp); // normal +x
        let (nd, _) = nodes_inside(&|_| true, Vec3::splat(-1.0), Vec3::splat(0.3), 60);
        let mut model = SurfelModel::default();
        model.add_collection("top", &top, [1.0; 3]);
        model.add_collection("side", &side, [1.0; 3]);
        model.clip.push((0, 1));
        let m = vec![1.0; nd.len()];
        let obj = SurfelObject::build(model, nd.clone(), m, &ObjectParams::default()).unwrap();
        let scene = DeformScene { objects: vec![obj.clone()], instances: vec![0] };
        let tracer = |clip_early: bool| {
            let mut t = DeformTracer::new(&scene, UpdateMode::Lazy, TraceParams { clip_early, ..TraceParams::default() }).unwrap();
            t.begin_frame(std::slice::from_ref(&nd)).unwrap();
            t
        };
        let (on, off) = (tracer(true), tracer(false));
        let ii = &on.inst[0];
        // The top's surfel nearest the edge x = 0 whose whole leaf ball is clipped.
        let c = &obj.model.collections[0];
        let s = (c.start as usize..c.end as usize)
            .filter(|&s| {
                let (sc, sr) = leaf_sphere(&on.surfel(ii, s));
                sc.y.abs() < 0.2 && on.ball_clipped(ii, s, sc, sr)
            })
            .min_by(|&a, &b| on.surfel(ii, a).p.x.total_cmp(&on.surfel(ii, b).p.x))
            .unwrap();
        let ds = on.surfel(ii, s);
        let (sc, sr) = leaf_sphere(&ds);
        assert!(sc.x > sr && sc.x < 2.0 * sr, "surfel at {sc}, radius {sr}");
        // On the top's plane, just inside the side's half-space x < 0.
        let x0 = Vec3::new(-1e-3, sc.y, 0.0);
        let ray = Ray::new(x0 + Vec3::Z, -Vec3::Z);
        let mut dc = DeformCounters::default();
        let full = off.iterate(0, s, u32::MAX, &ray, &ds, (1.0, x0), &mut dc);
        assert!(full.is_some_and(|h| (h.p - x0).length() < 1e-6), "the full test accepts x0: {full:?}");
        let early = on.iterate(0, s, u32::MAX, &ray, &ds, (1.0, x0), &mut dc);
        assert_eq!(early, full, "early clip against the full test");
    }
}
