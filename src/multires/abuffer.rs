//! The one-pixel A-buffer of a ray (Wand & Straßer §4.4, after Zwicker et al.'s surface
//! splatting): a depth-sorted list of surface fragments, each with summed attributes, a
//! weight sum and a depth interval. A new sample whose tolerance interval overlaps a fragment
//! is merged into it (attributes and weights added, intervals united); otherwise it becomes a
//! new fragment. Fragments are alpha-blended front to back with alpha = min(1, weight sum),
//! and the ray terminates early at alpha 1: by the paper's rule once the alpha of its
//! fragments reaches 1 ([`ABuffer::opaque`], checked by the traversal before each node), or
//! conservatively once the fragments lying wholly before the traversal front reach it
//! ([`ABuffer::opaque_before`]); `--termination` in [`super::trace::Termination`].
//!
//! *Which* fragments count for the paper's rule: those that begin before the traversal front
//! (the nearest depth a node still to be visited can reach). The traversal does not find
//! fragments in depth order — a large node (a floor's root, entered at the eye) hands out its
//! triangles long before the small nodes in front of them are visited — so a fragment that
//! lies wholly behind the front may still get geometry in front of it; counting it (the
//! first version did) let a floor behind a cube end the ray before the cube was reached.
//!
//! *Deviation* (`--coverage-masks`, [`super::mask`]): triangle fragments may carry coverage
//! masks; overlap within a fragment is then not counted as coverage ([`Frag::hidden`]) and
//! the compositing across fragments is corrected for it ([`Over`]).
//!
//! *Deviations* for the paper's §7 limitations (stop 39, default on): a fragment's alpha
//! counts a closed surface's near and far sides once (`--no-facing`, [`Frag::alpha`]), and
//! a fragment keeps the pieces of a second mesh apart and composites the two by depth, so a
//! floor behind an object's base does not average into it (`--merge-meshes`,
//! [`Frag::parts`]). With the split, each mesh of a fragment counts for the paper's
//! termination from where its own pieces begin (stop 40, [`ABuffer::opaque`]): a
//! silhouette's edge-on pieces reach deep, and the floor behind that joined them counted
//! from their beginning, ending defocused cones before the object's nearer pieces were found.
//!
//! Bounded memory: at most `cap` fragments (default 16); when full, the two adjacent
//! fragments with the smallest gap are merged (a documented approximation; it is counted in
//! `fragments_merged` like every merge).

use glam::Vec3;

/// Which element a fragment's differential properties come from (nearest-neighbour
/// sampling of ∇n, the paper's "cheaper alternative", §4.4): the sample of largest weight.
#[derive(Clone, Copy, Debug, PartialEq, Default)]
pub enum Elem {
    #[default]
    None,
    Point {
        leaf: u32,
        node: u32,
        idx: u32,
    },
    Tri {
        leaf: u32,
        tri: u32,
        b1: f32,
        b2: f32,
    },
    /// A point of an instance-tree slot ([`super::group`]).
    Group {
        slot: u32,
        idx: u32,
    },
}

#[derive(Clone, Copy, Debug, Default)]
pub struct Frag {
    /// Depth interval (world t).
    pub z0: f32,
    pub z1: f32,
    /// Weight sum, and Σ w·t.
    pub w: f32,
    pub wt: f32,
    /// Σ w·colour, Σ w·(kd, ks, shininess, reflect, transmit, ior, roughness), Σ w·normal.
    pub col: Vec3,
    pub props: [f32; 7],
    pub n: Vec3,
    pub best_w: f32,
    pub best: Elem,
    /// Sub-rays of the cone the fragment's pieces cover (`--coverage-masks`,
    /// [`super::mask`]); 0: unknown (points, tiny triangles), composited as in the paper.
    /// With two meshes (`other`), those of the first mesh's pieces; `other.mask` the rest.
    pub mask: u64,
    /// Of `w`, the weight of pieces that fell on sub-rays already covered by earlier pieces
    /// of the fragment (overlap, not coverage; [`Frag::alpha`]). 0 without masks. With two
    /// meshes, of the first mesh's pieces, overlapping its own; `other.hidden` the rest.
    pub hidden: f32,
    /// Of `w`, the weight of pieces whose normal faces away from the cone's origin (n·d > 0;
    /// `TraceParams::facing`, a deviation; 0 when off). See [`Frag::alpha`].
    pub wb: f32,
    /// The mesh of the fragment's first piece (`TraceParams::split_meshes`; 0 for all when
    /// off). Pieces of another mesh are summed apart in `other` as well.
    pub key: u32,
    /// Of the sums above, those of the pieces of one other mesh ([`Frag::parts`]).
    pub other: Group,
    /// Where the pieces of the first mesh (`key`) begin; `z0` is where all begin. Set by
    /// [`ABuffer::insert`].
    pub z0_key: f32,
    /// Σ w·n, Σ w and Σ w·t of the pieces of closed meshes facing away from the cone's
    /// origin: a solid's far side, which shading leaves out when its near side is there too
    /// (`TraceParams::facing`; [`super::trace`] `shade_visible`).
    pub nb: Vec3,
    pub wn: f32,
    pub wtn: f32,
}

/// [`Frag::key`] of pieces that join any group (the points of instance-tree slots, which
/// may hold several meshes and tile one surface with their neighbours): the paper's sum.
pub const ANY_MESH: u32 = u32::MAX;

/// The sums of a fragment's pieces from one mesh other than its first piece's.
#[derive(Clone, Copy, Debug, Default)]
pub struct Group {
    pub key: u32,
    /// Where the group's pieces begin (not a sum; [`Frag::z0_key`]).
    pub z0: f32,
    pub w: f32,
    pub wt: f32,
    pub col: Vec3,
    pub props: [f32; 7],
    pub n: Vec3,
    pub wb: f32,
    pub best_w: f32,
    pub best: Elem,
    /// [`Frag::nb`], [`Frag::wn`], [`Frag::wtn`].
    pub nb: Vec3,
    pub wn: f32,
    pub wtn: f32,
    /// The group's own [`Frag::mask`] and [`Frag::hidden`] (not sums: set by the merges).
    pub mask: u64,
    pub hidden: f32,
}

/// What [`ABuffer::insert`] takes: one point's or triangle's contribution, its sums as a
/// [`Group`] (`g.z0` where it begins, `g.best_w` its own weight), its depth interval's end
/// and its coverage. About half a [`Frag`], which also carries a second mesh's group: the
/// callers build and pass one per weighted element (stop 65: building and copying whole
/// fragments instead cost 2 % of a `complex` frame's instructions).
#[derive(Clone, Copy, Debug, Default)]
pub struct Piece {
    pub g: Group,
    pub z1: f32,
    /// [`Frag::mask`], [`Frag::hidden`].
    pub mask: u64,
    pub hidden: f32,
}

impl Piece {
    /// A piece over [z0, z1] of weight `w` at mean depth `t` (Σ w·t = w·t), of mesh `key`;
    /// the caller adds its shading sums.
    #[inline]
    pub fn new(z0: f32, z1: f32, w: f32, t: f32, key: u32) -> Piece {
        Piece { g: Group { key, z0, w, wt: w * t, best_w: w, ..Default::default() }, z1, ..Default::default() }
    }
    /// The fragment of this piece alone.
    pub fn frag(&self) -> Frag {
        let mut f = Frag { z0: self.g.z0, z0_key: self.g.z0, z1: self.z1, mask: self.mask, hidden: self.hidden, ..Default::default() };
        f.set_sums(&self.g);
        f
    }
}

impl Group {
    /// Adds `k` times `g`'s sums; for k > 0 `g`'s best element may take over.
    fn add_scaled(&mut self, g: &Group, k: f32) {
        self.w += k * g.w;
        self.wt += k * g.wt;
        self.col += k * g.col;
        for (a, b) in self.props.iter_mut().zip(g.props) {
            *a += k * b;
        }
        self.n += k * g.n;
        self.wb += k * g.wb;
        self.nb += k * g.nb;
        self.wn += k * g.wn;
        self.wtn += k * g.wtn;
        if k > 0.0 && g.best_w > self.best_w {
            self.best_w = g.best_w;
            self.best = g.best;
        }
    }
    fn add(&mut self, g: &Group) {
        self.add_scaled(g, 1.0);
    }
}

impl Frag {
    /// All the fragment's sums as a group (its first mesh's key and best element).
    fn sums(&self) -> Group {
        Group {
            key: self.key,
            z0: self.z0_key,
            w: self.w,
            wt: self.wt,
            col: self.col,
            props: self.props,
            n: self.n,
            wb: self.wb,
            best_w: self.best_w,
            best: self.best,
            nb: self.nb,
            wn: self.wn,
            wtn: self.wtn,
            mask: self.mask,
            hidden: self.hidden,
        }
    }
    /// Sets the fragment's sums, key and best element from `g`.
    fn set_sums(&mut self, g: &Group) {
        (self.key, self.w, self.wt, self.col, self.props, self.n) = (g.key, g.w, g.wt, g.col, g.props, g.n);
        (self.wb, self.best_w, self.best, self.nb, self.wn, self.wtn) = (g.wb, g.best_w, g.best, g.nb, g.wn, g.wtn);
    }
    /// The sums of the pieces of the fragment's first mesh (`key`): all but `other`'s.
    fn first(&self) -> Group {
        let mut g = self.sums();
        g.add_scaled(&self.other, -1.0);
        g
    }

    fn absorb(&mut self, s: &Frag) {
        self.absorb_with(s, true);
    }
    /// [`Frag::absorb`]; `piece_in_place` false takes the general path for every merge
    /// (the reference in the tests).
    fn absorb_with(&mut self, s: &Frag, piece_in_place: bool) {
        // Nearly every merge of two fragments is of a single group (`other` all zeros: it
        // only ever takes groups of positive weight).
        if piece_in_place && !(s.other.w > 0.0) {
            let first = self.absorb_group(&s.sums());
            self.absorb_mask(first, s.w, s.mask, s.hidden);
        } else {
            self.absorb_groups(s);
        }
        self.absorb_extent(s.z0, s.z1);
    }
    /// Merges one piece: [`Frag::absorb`] of `p.frag()`, bit for bit, without building it.
    #[inline]
    fn absorb_piece(&mut self, p: &Piece) {
        let first = self.absorb_group(&p.g);
        self.absorb_mask(first, p.g.w, p.mask, p.hidden);
        self.absorb_extent(p.g.z0, p.z1);
    }
    /// The depth interval of a merge of pieces [z0, z1].
    #[inline]
    fn absorb_extent(&mut self, z0: f32, z1: f32) {
        self.z0 = self.z0.min(z0);
        self.z1 = self.z1.max(z1);
    }
    /// The coverage of pieces of weight `w` that joined the first group (`first`) or
    /// `other`. Overlap within the group (`--coverage-masks`): the share of the new pieces'
    /// coverage that falls on sub-rays the group already covers is not coverage. Overlap
    /// with the other group is occlusion between the two parts, which [`Over`] composites
    /// by depth (§4.4). (Until the ray-cone review one mask served both groups: a floor
    /// behind an object's base, covering the object's sub-rays, was charged to the object's
    /// part as hidden weight, giving it a negative alpha; test
    /// `overlap_with_another_mesh_is_not_hidden_in_the_first`.)
    #[inline]
    fn absorb_mask(&mut self, first: bool, w: f32, mask: u64, hidden: f32) {
        let (m, h) = if first { (&mut self.mask, &mut self.hidden) } else { (&mut self.other.mask, &mut self.other.hidden) };
        *h += hidden;
        if mask & *m != 0 {
            let over = (mask & *m).count_ones() as f32 / mask.count_ones() as f32;
            *h += (w - hidden).max(0.0) * over;
        }
        *m |= mask;
    }

    /// [`Frag::absorb`]'s sums for one group `s` (a piece, or a fragment of one mesh;
    /// `s.z0` where its pieces begin), added in place: the general path's result bit for bit
    /// (its group of `s` is `s`'s sums less an empty `other`, added with factor 1), without
    /// its copies of the groups (stop 64: `absorb` was 7 % of a `complex` frame, mostly
    /// moving groups through the stack).
    /// Returns whether `s` counts with the first group (also when it has no weight).
    /// Inlined into [`Frag::absorb_piece`] (a merge per inserted piece: called, it took a
    /// third of its 75 instructions to pass the group and save registers; −1.1 % of
    /// `complex`'s cone instructions).
    #[inline(always)]
    fn absorb_group(&mut self, s: &Group) -> bool {
        let joins = s.w > 0.0;
        let mut to_first = false;
        if joins {
            // The group `s` joins, as `absorb_groups` decides it.
            to_first = if s.key == self.key || s.key == ANY_MESH || self.key == ANY_MESH {
                true
            } else if self.other.w > 0.0 && s.key != self.other.key {
                let (mw, mwt) = (self.w - self.other.w, self.wt - self.other.wt);
                let gt = s.wt / s.w;
                let ta = if mw > 0.0 { mwt / mw } else { gt };
                (gt - ta).abs() <= (gt - self.other.wt / self.other.w).abs()
            } else {
                false
            };
            if to_first {
                if self.key == ANY_MESH {
                    self.key = s.key;
                }
                self.z0_key = self.z0_key.min(s.z0);
            } else {
                if !(self.other.w > 0.0) {
                    (self.other.key, self.other.z0) = (s.key, s.z0);
                }
                self.other.add(s);
                self.other.z0 = self.other.z0.min(s.z0);
            }
        }
        self.w += s.w;
        self.wt += s.wt;
        self.col += s.col;
        for (a, b) in self.props.iter_mut().zip(s.props) {
            *a += b;
        }
        self.n += s.n;
        self.wb += s.wb;
        self.nb += s.nb;
        self.wn += s.wn;
        self.wtn += s.wtn;
        // The general path's best of the pieces that joined the first group.
        let (bw, b) = if to_first && s.best_w > 0.0 { (s.best_w, s.best) } else { (0.0, Elem::None) };
        if bw > self.best_w {
            (self.best_w, self.best) = (bw, b);
        }
        to_first || !joins
    }

    /// [`Frag::absorb`]'s sums and best element, the general path: `s` may hold two meshes.
    fn absorb_groups(&mut self, s: &Frag) {
        // Split meshes: each of `s`'s groups joins the one here of its mesh; a new mesh
        // becomes `other` when that is free, else joins the group nearer in depth.
        let mut to_first = Group::default();
        // The first group as it grows in this loop: the totals (`sums`) take `s` only after
        // it, so `first()` (totals less `other`) is wrong once `other` has taken a group here.
        // (Until stop 49 it was used: absorbing a two-mesh fragment could put its second mesh
        // with the wrong group; review finding, test `third_mesh_joins_the_nearer_group`.)
        // Only read where `other` is taken, which needs a second mesh here or in `s`: the
        // common single-mesh merge skips the copy.
        let mut mine = if self.other.w > 0.0 || s.other.w > 0.0 { self.first() } else { Group::default() };
        for (g, gz0) in [(s.first(), s.z0_key), (s.other, s.other.z0)] {
            if !(g.w > 0.0) {
                self.absorb_mask(true, g.w, g.mask, g.hidden);
                continue;
            }
            let joins_first = if g.key == self.key || g.key == ANY_MESH || self.key == ANY_MESH {
                if self.key == ANY_MESH {
                    self.key = g.key;
                }
                true
            } else if self.other.w > 0.0 && g.key != self.other.key {
                let gt = g.wt / g.w;
                let ta = if mine.w > 0.0 { mine.wt / mine.w } else { gt };
                (gt - ta).abs() <= (gt - self.other.wt / self.other.w).abs()
            } else {
                false
            };
            self.absorb_mask(joins_first, g.w, g.mask, g.hidden);
            if joins_first {
                to_first.add(&g);
                mine.add(&g);
                self.z0_key = self.z0_key.min(gz0);
            } else {
                if !(self.other.w > 0.0) {
                    (self.other.key, self.other.z0) = (g.key, gz0);
                }
                self.other.add(&g);
                self.other.z0 = self.other.z0.min(gz0);
            }
        }
        // The totals; the best element only from the pieces that joined the first group.
        let mut t = self.sums();
        t.add_scaled(&s.sums(), 1.0);
        (t.best_w, t.best) = (self.best_w, self.best);
        self.set_sums(&t);
        if to_first.best_w > self.best_w {
            self.best_w = to_first.best_w;
            self.best = to_first.best;
        }
    }
    /// Coverage: min(1, weight sum) (§4.4), less the weight of pieces that overlap others of
    /// the fragment by their coverage masks (`hidden`, a deviation; 0 without masks).
    ///
    /// *Deviation* (`TraceParams::facing`, default on): at most the larger of the weights
    /// facing towards the cone's origin and away from it, max(w − wb, wb). A line through a
    /// closed surface enters it as often as it leaves, so where a wide footprint merges a
    /// solid's near and far sides into one fragment (soft shadows, silhouettes, defocus)
    /// each side alone measures the solid's coverage and their sum counts it twice — the
    /// paper's overestimated opacity at silhouettes and soft shadows (§7). A single sheet
    /// (a floor, a leaf) has all its weight on one side and keeps it. With `wb` = 0 (off)
    /// this is the paper's rule, bit for bit.
    #[inline]
    pub fn alpha(&self) -> f32 {
        if self.other.w > 0.0 {
            // The two parts as `Over` composites them (with coverage masks, the farther
            // part's share scaled by how much of it the nearer one leaves visible), so that
            // early termination sees the alpha the pixel gets. Without masks this is
            // a + (1 − a)·b, bit for bit.
            let ([a, b], _) = self.parts();
            let mut o = Over::default();
            o.add(&a);
            o.add(&b);
            return o.acc;
        }
        (self.w - self.hidden).min((self.w - self.wb).max(self.wb)).min(1.0)
    }
    /// The fragment as its meshes' groups, nearer mean depth first: two fragments when it
    /// holds pieces of two meshes (`TraceParams::split_meshes`), else itself alone. Within
    /// one footprint and depth interval, pieces of different meshes (an object and the floor
    /// it stands on) are separate surfaces, of which the nearer hides the farther; the
    /// paper's sum lets a floor behind an object's base shine through the object (its §7:
    /// "the compositing step merges the floor and the base of the bunny into a single
    /// fragment"). Each group composites front to back as a fragment of its own.
    pub fn parts(&self) -> ([Frag; 2], usize) {
        if !(self.other.w > 0.0) {
            return ([*self, *self], 1);
        }
        let part = |g: Group, z0: f32, mask: u64, hidden: f32| {
            let mut f = Frag { z0, z0_key: z0, z1: self.z1, mask, hidden, ..Default::default() };
            f.set_sums(&g);
            f
        };
        let (a, b) =
            (part(self.first(), self.z0_key, self.mask, self.hidden), part(self.other, self.other.z0, self.other.mask, self.other.hidden));
        if a.t() <= b.t() {
            ([a, b], 2)
        } else {
            ([b, a], 2)
        }
    }
    /// Mean depth.
    pub fn t(&self) -> f32 {
        if self.w > 0.0 {
            self.wt / self.w
        } else {
            0.5 * (self.z0 + self.z1)
        }
    }
}

pub struct ABuffer {
    pub frags: Vec<Frag>,
    pub cap: usize,
    /// Fragments [0, n_final) lie wholly in front of the traversal front.
    /// Their compositing ([`Over`], coverage masks included).
    n_final: usize,
    over_final: Over,
    /// Fragments [0, n_begun) begin before the last traversal front `front`; `over_begun`
    /// is their compositing. Valid unless `dirty` (an insertion since).
    n_begun: usize,
    over_begun: Over,
    front: f32,
    dirty: bool,
    pub merges: u64,
}

/// Alpha at which a ray counts as opaque (early termination).
pub const OPAQUE: f32 = 0.999;

impl ABuffer {
    pub fn new(cap: usize) -> Self {
        ABuffer {
            frags: Vec::with_capacity(cap.max(2) + 1),
            cap: cap.max(2),
            n_final: 0,
            over_final: Over::default(),
            n_begun: 0,
            over_begun: Over::default(),
            front: f32::NEG_INFINITY,
            dirty: false,
            merges: 0,
        }
    }
    pub fn clear(&mut self) {
        self.frags.clear();
        self.n_final = 0;
        self.over_final = Over::default();
        self.n_begun = 0;
        self.over_begun = Over::default();
        self.front = f32::NEG_INFINITY;
        self.dirty = false;
        self.merges = 0;
    }

    /// Inserts one sample (a single point or triangle).
    pub fn insert(&mut self, s: &Piece) {
        let (z0, z1) = (s.g.z0, s.z1);
        self.dirty = true;
        // First fragment that does not end before the sample starts.
        let i = self.frags.partition_point(|f| f.z1 < z0);
        // The fragments from the first one changed here on are no longer known to be final
        // (`opaque_before` checks them again): a merge can grow a final fragment past the
        // front. (Until stop 49 only the prefix's length was capped; review finding, test
        // `a_final_fragment_grown_past_the_front_is_not_final`.)
        let mut touched = i;
        if i < self.frags.len() && self.frags[i].z0 <= z1 {
            self.frags[i].absorb_piece(s);
            self.merges += 1;
            // The grown interval may now reach the following fragments.
            while i + 1 < self.frags.len() && self.frags[i + 1].z0 <= self.frags[i].z1 {
                let next = self.frags.remove(i + 1);
                self.frags[i].absorb(&next);
                self.merges += 1;
            }
            // ... or the previous one (the interval grew towards the front).
            if i > 0 && self.frags[i - 1].z1 >= self.frags[i].z0 {
                let cur = self.frags.remove(i);
                self.frags[i - 1].absorb(&cur);
                self.merges += 1;
                touched = i - 1;
            }
        } else {
            self.frags.insert(i, s.frag());
            if self.frags.len() > self.cap {
                touched = touched.min(self.merge_closest());
            }
        }
        self.n_final = self.n_final.min(touched);
    }

    /// Merges the two fragments closest in depth; returns the index of the merged one.
    fn merge_closest(&mut self) -> usize {
        let mut best = (f32::INFINITY, 0);
        for i in 0..self.frags.len() - 1 {
            let gap = self.frags[i + 1].z0 - self.frags[i].z1;
            if gap < best.0 {
                best = (gap, i);
            }
        }
        let i = best.1;
        let next = self.frags.remove(i + 1);
        self.frags[i].absorb(&next);
        self.merges += 1;
        i
    }

    /// Called with the nearest depth the traversal can still reach: finalises the fragments
    /// that end before it and reports whether their alpha has reached 1 (early termination).
    pub fn opaque_before(&mut self, t_front: f32) -> bool {
        // Fragments may have been merged since; recompute the final prefix conservatively.
        if self.n_final > 0 {
            self.over_final = Over::default();
            for f in &self.frags[..self.n_final] {
                self.over_final.add_frag(f);
            }
        }
        while self.n_final < self.frags.len() && self.frags[self.n_final].z1 < t_front {
            self.over_final.add_frag(&self.frags[self.n_final]);
            self.n_final += 1;
        }
        self.over_final.acc >= OPAQUE
    }

    /// The paper's early termination test (§4.4): has the alpha of the ray reached 1? Counts
    /// the fragments that begin before `t_front`, the nearest depth the traversal can still
    /// reach (module docs); a fragment straddling the front counts with the weight gathered so
    /// far. Called before every node; incremental while the front advances and nothing is
    /// inserted.
    /// Inlined into the traversal's loop (stop 65: its call was half its cost, −0.6 % of
    /// the render's instructions).
    #[inline]
    pub fn opaque(&mut self, t_front: f32) -> bool {
        if self.dirty || t_front < self.front {
            self.n_begun = 0;
            self.over_begun = Over::default();
            self.dirty = false;
        }
        self.front = t_front;
        while self.n_begun < self.frags.len() && self.frags[self.n_begun].z0 < t_front {
            let f = &self.frags[self.n_begun];
            if f.other.w > 0.0 && f.z0_key.max(f.other.z0) >= t_front {
                // Two meshes, one of which begins past the front (`split_meshes`): only the
                // part that has begun counts, and the fragment stays open (*deviation*: the
                // paper's fragment begins where its first piece does, so an object's
                // silhouette, whose edge-on pieces reach deep, let the floor behind it end
                // the cone before the object's nearer pieces were found).
                let ([a, b], _) = f.parts();
                let mut o = self.over_begun;
                o.add(if a.z0 < t_front { &a } else { &b });
                return o.acc >= OPAQUE;
            }
            self.over_begun.add_frag(f);
            self.n_begun += 1;
        }
        self.over_begun.acc >= OPAQUE
    }

    /// Total alpha of all fragments, front to back ([`Over`]).
    pub fn alpha(&self) -> f32 {
        let mut o = Over::default();
        for f in &self.frags {
            o.add_frag(f);
        }
        o.acc
    }
}

/// Front-to-back compositing of a ray's fragments (§4.4): each fragment gets the share
/// k = α·(1 − A) of the pixel, A the alpha in front of it. With coverage masks
/// ([`super::mask`], a deviation) k is scaled by how visible the fragment's sub-rays are
/// compared with all sub-rays: r = (|m ∧ ¬M|/|m| + ε) / (|¬M|/64 + ε), M the sub-rays
/// covered in front. Independent pieces get r ≈ 1 (the paper), a piece behind the same spot
/// of one in front r ≈ 0, a surface covering the whole footprint r = 1 exactly. Without
/// masks (all 0) this is the paper's compositing, bit for bit.
#[derive(Clone, Copy, Debug, Default)]
pub struct Over {
    /// Alpha composited so far.
    pub acc: f32,
    covered: u64,
}

impl Over {
    /// Adds the next fragment (front to back) and returns its share of the pixel.
    #[inline]
    pub fn add(&mut self, f: &Frag) -> f32 {
        let left = 1.0 - self.acc;
        let mut k = left * f.alpha();
        if f.mask != 0 && self.covered != 0 {
            const EPS: f32 = 1.0 / 128.0;
            let mine = (f.mask & !self.covered).count_ones() as f32 / f.mask.count_ones() as f32;
            let all = super::mask::share(!self.covered);
            k = (k * (mine + EPS) / (all + EPS)).min(left);
        }
        self.covered |= f.mask;
        self.acc += k;
        k
    }
    /// Adds a whole fragment: its parts ([`Frag::parts`]) in turn, as the pixel composites
    /// them, so that early termination sees the alpha the pixel gets, the coverage masks of
    /// the fragments in front included (until a review finding the termination tests
    /// composited each fragment's [`Frag::alpha`] without them; test
    /// `leaves_stacked_on_one_half_do_not_end_the_ray`).
    #[inline]
    pub fn add_frag(&mut self, f: &Frag) {
        if f.other.w > 0.0 {
            let (p, _) = f.parts();
            self.add(&p[0]);
            self.add(&p[1]);
        } else {
            self.add(f);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The piece of a fragment built as one (no second mesh, `z0_key` unset).
    fn pc(f: Frag) -> Piece {
        assert!(f.z0_key == 0.0 && f.other.w == 0.0);
        Piece { g: Group { z0: f.z0, ..f.sums() }, z1: f.z1, mask: f.mask, hidden: f.hidden }
    }

    fn smp(t: f32, d: f32, w: f32, c: Vec3) -> Frag {
        Frag { z0: t - d, z1: t + d, w, wt: w * t, col: c * w, best_w: w, ..Default::default() }
    }

    #[test]
    fn overlapping_samples_merge_and_others_sort() {
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(smp(5.0, 0.1, 0.5, Vec3::X)));
        ab.insert(&pc(smp(2.0, 0.1, 0.3, Vec3::Y)));
        ab.insert(&pc(smp(5.15, 0.1, 0.6, Vec3::X)));
        assert_eq!(ab.frags.len(), 2);
        assert!(ab.frags[0].z1 < ab.frags[1].z0);
        assert!((ab.frags[1].w - 1.1).abs() < 1e-6);
        assert!((ab.frags[1].z0 - 4.9).abs() < 1e-6 && (ab.frags[1].z1 - 5.25).abs() < 1e-6);
        // A sample bridging the two merges all three.
        ab.insert(&pc(smp(3.5, 1.45, 0.1, Vec3::Z)));
        assert_eq!(ab.frags.len(), 1);
        assert_eq!(ab.merges, 3);
        assert!((ab.frags[0].w - 1.5).abs() < 1e-6);
    }

    /// The in-place merges of a single-group fragment and of a [`Piece`] give the general
    /// path's fragment bit for bit:
    /// random pieces of three meshes and of instance-tree slots (`ANY_MESH`), some of zero
    /// weight, with and without coverage masks, absorbed in random order, so that pieces
    /// join the first group, start the `other` group, join it, or go to the nearer one.
    #[test]
    fn piece_merge_in_place_equals_the_general_path() {
        let mut r = crate::core::rng::Sampler::new(64, 0, 0);
        let frag = |r: &mut crate::core::rng::Sampler| {
            let (t, w) = (1.0 + 9.0 * r.next(), if r.next() < 0.1 { 0.0 } else { r.next() });
            let key = [0, 1, 2, ANY_MESH][(r.next() * 4.0) as usize % 4];
            let e = Elem::Point { leaf: (r.next() * 9.0) as u32, node: 1, idx: (r.next() * 99.0) as u32 };
            Frag {
                z0: t - r.next(),
                z1: t + r.next(),
                w,
                wt: w * t,
                col: Vec3::new(r.next(), r.next(), r.next()) * w,
                props: [r.next(); 7].map(|v| v * w),
                n: Vec3::new(r.next() - 0.5, r.next(), r.next()) * w,
                best_w: w,
                best: e,
                mask: if r.next() < 0.5 { (r.next() * 1e9) as u64 } else { 0 },
                hidden: 0.1 * w * r.next(),
                wb: if r.next() < 0.3 { w } else { 0.0 },
                key,
                z0_key: t - r.next(),
                nb: Vec3::splat(r.next() * w),
                wn: w,
                wtn: w * t,
                ..Default::default()
            }
        };
        let (mut into_one, mut into_two, mut by_depth) = (0, 0, 0);
        for _ in 0..2000 {
            let mut a = frag(&mut r);
            let mut b = a;
            let mut pa = a;
            for _ in 0..(r.next() * 6.0) as usize {
                let s = frag(&mut r);
                if s.w > 0.0 && !(a.other.w > 0.0) {
                    into_one += 1;
                } else if s.w > 0.0 {
                    into_two += 1;
                    if ![a.key, a.other.key, ANY_MESH].contains(&s.key) && a.key != ANY_MESH {
                        by_depth += 1;
                    }
                }
                a.absorb_with(&s, true);
                b.absorb_with(&s, false);
                assert_eq!(format!("{a:?}"), format!("{b:?}"));
                // The same as a piece (which begins where its interval does).
                let p = pc(Frag { z0_key: 0.0, ..s });
                let mut c = pa;
                pa.absorb_piece(&p);
                c.absorb_with(&p.frag(), false);
                assert_eq!(format!("{pa:?}"), format!("{c:?}"));
            }
        }
        assert!(into_one > 1000 && into_two > 1000 && by_depth > 200, "{into_one} {into_two} {by_depth}");
    }

    /// `TraceParams::facing`: a solid's near side (facing the origin) and far side merged
    /// into one fragment cover the footprint once; a single sheet keeps its sum either way.
    #[test]
    fn near_and_far_sides_of_a_solid_count_once() {
        let far = |t: f32, w: f32| Frag { wb: w, ..smp(t, 0.5, w, Vec3::ONE) };
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(smp(2.0, 0.5, 0.4, Vec3::ONE)));
        ab.insert(&pc(far(2.6, 0.45)));
        assert_eq!(ab.frags.len(), 1, "merged");
        assert!((ab.alpha() - 0.45).abs() < 1e-6, "max of the sides, not their sum 0.85: {}", ab.alpha());
        // Both pieces of one sheet face the same way: summed as in the paper, from either side.
        for mk in [|t, w| smp(t, 0.5, w, Vec3::ONE), far] {
            let mut ab = ABuffer::new(16);
            ab.insert(&pc(mk(2.0, 0.4)));
            ab.insert(&pc(mk(2.6, 0.45)));
            assert!((ab.alpha() - 0.85).abs() < 1e-6, "{}", ab.alpha());
        }
        // Without facing (wb = 0 everywhere) the rule is the paper's, and masks still apply.
        let f = Frag { w: 1.4, hidden: 0.5, ..Default::default() };
        assert!((f.alpha() - 0.9).abs() < 1e-6);
        let f = Frag { w: 1.4, wb: 0.6, hidden: 0.1, ..Default::default() };
        assert!((f.alpha() - 0.8).abs() < 1e-6, "{}", f.alpha());
    }

    /// `TraceParams::split_meshes`: an object's face and the floor behind its base, merged
    /// by their depth intervals, composite front to back as two surfaces: the face hides
    /// the floor behind it, where the paper's sum averages the floor's colour in by weight.
    #[test]
    fn pieces_of_two_meshes_composite_by_depth() {
        let piece = |t: f32, w: f32, c: Vec3, key: u32| Frag { key, ..smp(t, 0.4, w, c) };
        for split in [true, false] {
            let (face, floor) = if split { (1, 0) } else { (0, 0) };
            let mut ab = ABuffer::new(16);
            ab.insert(&pc(piece(6.6, 0.87, Vec3::X, face)));
            ab.insert(&pc(piece(6.73, 1.0, Vec3::Y, floor)));
            assert_eq!(ab.frags.len(), 1, "merged by depth");
            let (parts, n) = ab.frags[0].parts();
            let mut over = Over::default();
            let col: Vec3 = parts[..n].iter().map(|p| p.col / p.w * over.add(p)).sum();
            assert!((ab.alpha() - 1.0).abs() < 1e-6);
            if split {
                assert_eq!(n, 2);
                assert!((col - Vec3::new(0.87, 0.13, 0.0)).length() < 1e-5, "the face in front: {col}");
            } else {
                assert_eq!(n, 1);
                assert!((col - Vec3::new(0.87, 1.0, 0.0) / 1.87).length() < 1e-5, "the paper's weighted mean: {col}");
            }
        }
        // A third mesh joins the group nearer in depth; the sums stay whole.
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(piece(6.6, 0.5, Vec3::X, 1)));
        ab.insert(&pc(piece(6.9, 0.5, Vec3::Y, 2)));
        ab.insert(&pc(piece(6.85, 0.25, Vec3::Z, 3)));
        let f = &ab.frags[0];
        assert!((f.w - 1.25).abs() < 1e-6 && (f.other.w - 0.75).abs() < 1e-6 && f.other.key == 2, "{:?}", f.other);
    }

    /// A silhouette's edge-on piece reaches deep (here from 5.4); the floor behind it joins
    /// its fragment but begins only at 6.8. The paper's termination counted the floor from
    /// 5.4 and ended the cone at any front past it; each mesh now counts from where its own
    /// pieces begin, and the parts keep those beginnings.
    #[test]
    fn each_mesh_of_a_fragment_counts_from_its_own_beginning() {
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(Frag { key: 1, ..smp(6.4, 1.0, 0.1, Vec3::X) }));
        ab.insert(&pc(Frag { key: 0, ..smp(6.9, 0.1, 1.0, Vec3::Y) }));
        assert_eq!(ab.frags.len(), 1, "merged by depth");
        let f = ab.frags[0];
        assert!((f.z0 - 5.4).abs() < 1e-6 && (f.z0_key - 5.4).abs() < 1e-6 && (f.other.z0 - 6.8).abs() < 1e-6, "{f:?}");
        assert!(!ab.opaque(6.0), "the floor has not begun at 6.0");
        assert!(ab.opaque(6.85), "the floor has begun at 6.85");
        assert!(!ab.opaque(6.0), "a front moved back recounts");
        let (parts, n) = f.parts();
        assert_eq!(n, 2);
        assert!((parts[0].z0 - 5.4).abs() < 1e-6 && (parts[1].z0 - 6.8).abs() < 1e-6);
        // Merged into a third fragment's, the beginnings travel with their groups.
        ab.insert(&pc(Frag { key: 0, ..smp(6.7, 0.1, 0.2, Vec3::Y) }));
        let f = ab.frags[0];
        assert!((f.other.z0 - 6.6).abs() < 1e-6 && (f.z0_key - 5.4).abs() < 1e-6, "{f:?}");
    }

    #[test]
    fn alpha_and_early_termination() {
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(smp(1.0, 0.1, 0.5, Vec3::ONE)));
        assert!(!ab.opaque_before(2.0));
        ab.insert(&pc(smp(3.0, 0.1, 1.7, Vec3::ONE)));
        assert!(!ab.opaque_before(3.0), "not final while the front is inside it");
        assert!(ab.opaque_before(3.2));
        assert!((ab.alpha() - 1.0).abs() < 1e-6);
        let mut ab = ABuffer::new(16);
        assert!(!ab.opaque(1.0));
        ab.insert(&pc(smp(1.0, 0.1, 0.6, Vec3::ONE)));
        assert!(!ab.opaque(1.0));
        ab.insert(&pc(smp(1.05, 0.1, 0.6, Vec3::ONE)));
        assert!(ab.opaque(1.0), "merged weight 1.2: the ray is opaque even with the front inside");
    }

    /// An opaque fragment found before the geometry in front of it (a floor's big triangle
    /// from a node entered at the eye) must not end the ray while the front is before it.
    #[test]
    fn fragments_behind_the_front_do_not_terminate() {
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(smp(8.0, 0.2, 1.0, Vec3::X)));
        assert!(!ab.opaque(2.0), "the floor at 8 is behind the front at 2");
        assert!(!ab.opaque(7.7));
        assert!(ab.opaque(7.9), "the front has reached the floor");
        // The cube in front, found later, is composited first.
        ab.insert(&pc(smp(5.0, 0.1, 1.0, Vec3::Y)));
        assert!(ab.opaque(5.0));
        assert_eq!(ab.frags[0].col, Vec3::Y);
        // A front that moves back (a node entered nearer) recounts.
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(smp(8.0, 0.2, 1.0, Vec3::X)));
        assert!(ab.opaque(9.0));
        assert!(!ab.opaque(3.0));
    }

    /// `--coverage-masks`: pieces on the same sub-rays count once, within a fragment and
    /// across fragments; pieces on disjoint sub-rays add up as in the paper; a surface behind
    /// that covers every sub-ray fills exactly what is left.
    #[test]
    fn coverage_masks_count_overlap_once() {
        let masked = |t: f32, w: f32, mask: u64| Frag { mask, ..smp(t, 0.1, w, Vec3::ONE) };
        let (left, right) = (0x0000_0000_ffff_ffffu64, 0xffff_ffff_0000_0000u64);
        // One fragment: two halves of one surface, then the same half twice.
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(masked(1.0, 0.5, left)));
        ab.insert(&pc(masked(1.02, 0.5, right)));
        assert_eq!(ab.frags.len(), 1);
        assert!((ab.alpha() - 1.0).abs() < 1e-6);
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(masked(1.0, 0.5, left)));
        ab.insert(&pc(masked(1.02, 0.5, left)));
        assert!((ab.alpha() - 0.5).abs() < 1e-6, "{}", ab.alpha());
        assert!((ab.frags[0].w - 1.0).abs() < 1e-6, "the weight sum (shading) is unchanged");
        // Half of a piece over covered sub-rays: half its weight is hidden.
        ab.insert(&pc(masked(1.01, 0.2, 0x0000_ffff_ffff_0000)));
        assert!((ab.alpha() - 0.6).abs() < 1e-6, "{}", ab.alpha());
        // Unmasked pieces add as in the paper.
        ab.insert(&pc(smp(1.01, 0.1, 0.1, Vec3::ONE)));
        assert!((ab.alpha() - 0.7).abs() < 1e-6);
        // Across fragments: a leaf behind the same half of a leaf in front is hidden; one
        // behind the other half shows whole; a covering wall fills exactly what is left.
        for (back, want) in [(left, 0.5), (right, 1.0)] {
            let mut ab = ABuffer::new(16);
            ab.insert(&pc(masked(1.0, 0.5, left)));
            ab.insert(&pc(masked(5.0, 0.5, back)));
            assert_eq!(ab.frags.len(), 2);
            assert!((ab.alpha() - want).abs() < 0.01, "{} vs {want}", ab.alpha());
        }
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(masked(1.0, 0.37, left)));
        ab.insert(&pc(masked(5.0, 1.0, u64::MAX)));
        assert!((ab.alpha() - 1.0).abs() < 1e-6);
        let mut o = Over::default();
        assert!((o.add(&ab.frags[0]) - 0.37).abs() < 1e-6);
        assert!((o.add(&ab.frags[1]) - 0.63).abs() < 1e-6);
        // Without masks: the paper's compositing.
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(smp(1.0, 0.1, 0.5, Vec3::ONE)));
        ab.insert(&pc(smp(5.0, 0.1, 0.5, Vec3::ONE)));
        assert!((ab.alpha() - 0.75).abs() < 1e-6);
    }

    /// `--coverage-masks` with split meshes: an object's piece on the left half of the
    /// footprint and the floor behind it, covering every sub-ray, merged into one fragment.
    /// The floor's overlap with the object is occlusion between the two parts (composited
    /// front to back), not overlap within the object: the object's part keeps its alpha 0.3
    /// and the floor fills the rest. (The whole fragment's hidden weight, 0.5 of the floor's,
    /// was charged to the object's part: alpha −0.2, a negative share of the pixel and 1.2
    /// for the floor.)
    #[test]
    fn overlap_with_another_mesh_is_not_hidden_in_the_first() {
        let masked = |t: f32, w: f32, mask: u64, key: u32| Frag { mask, key, ..smp(t, 0.4, w, Vec3::ONE) };
        let left = 0x0000_0000_ffff_ffffu64;
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(masked(6.6, 0.3, left, 1)));
        ab.insert(&pc(masked(6.73, 1.0, u64::MAX, 0)));
        assert_eq!(ab.frags.len(), 1, "merged by depth");
        let (parts, n) = ab.frags[0].parts();
        assert_eq!(n, 2);
        let mut o = Over::default();
        let k: Vec<f32> = parts[..n].iter().map(|p| o.add(p)).collect();
        assert!((k[0] - 0.3).abs() < 1e-6 && (k[1] - 0.7).abs() < 1e-6, "shares {k:?}");
        assert!((ab.alpha() - 1.0).abs() < 1e-6, "{}", ab.alpha());
        // Overlap within one mesh is still hidden.
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(masked(6.6, 0.3, left, 1)));
        ab.insert(&pc(masked(6.65, 0.3, left, 1)));
        assert!((ab.alpha() - 0.3).abs() < 1e-6, "{}", ab.alpha());
    }

    /// A two-mesh fragment's alpha is what `Over` composites from its parts, masks included:
    /// an object on the left half of the footprint (0.3) and a floor piece (0.5) only behind
    /// it. `Frag::alpha` (early termination) gave 0.3 + 0.7·0.5 = 0.65, the pixel 0.305.
    #[test]
    fn a_two_mesh_fragments_alpha_is_its_compositing() {
        let masked = |t: f32, w: f32, mask: u64, key: u32| Frag { mask, key, ..smp(t, 0.4, w, Vec3::ONE) };
        let left = 0x0000_0000_ffff_ffffu64;
        for floor_mask in [left, u64::MAX, 0] {
            let mut ab = ABuffer::new(16);
            ab.insert(&pc(masked(6.6, 0.3, left, 1)));
            ab.insert(&pc(masked(6.73, 0.5, floor_mask, 0)));
            assert_eq!(ab.frags.len(), 1, "merged by depth");
            let f = ab.frags[0];
            let (parts, n) = f.parts();
            assert_eq!(n, 2);
            let mut o = Over::default();
            parts[..n].iter().for_each(|p| _ = o.add(p));
            assert_eq!(f.alpha(), o.acc, "floor mask {floor_mask:x}");
            assert_eq!(ab.alpha(), o.acc);
        }
    }

    /// `--coverage-masks`: early termination sees the alpha the pixel gets across fragments
    /// too. Twelve leaves on the same half of the footprint, one behind the other, cover that
    /// half: the pixel's alpha is about 0.54 (`Over`), and the ray must go on to the wall
    /// behind. (Review finding: both termination tests composited the fragments' alphas
    /// without their masks, 1 − 0.5¹² = 0.9998, and ended the ray there: the wall was never
    /// reached and the background showed through the other half.)
    #[test]
    fn leaves_stacked_on_one_half_do_not_end_the_ray() {
        let masked = |t: f32, w: f32, mask: u64| Frag { mask, ..smp(t, 0.1, w, Vec3::ONE) };
        let left = 0x0000_0000_ffff_ffffu64;
        let mut ab = ABuffer::new(16);
        for i in 0..12 {
            ab.insert(&pc(masked(1.0 + i as f32, 0.5, left)));
        }
        assert_eq!(ab.frags.len(), 12);
        assert!(ab.alpha() < 0.6, "{}", ab.alpha());
        assert!(!ab.opaque(20.0), "paper's rule: alpha {} only", ab.alpha());
        assert!(!ab.opaque_before(20.0), "final rule: alpha {} only", ab.alpha());
        // The wall behind fills the other half.
        ab.insert(&pc(masked(15.0, 1.0, u64::MAX)));
        assert!(ab.alpha() >= OPAQUE, "{}", ab.alpha());
        assert!(ab.opaque(20.0));
        assert!(ab.opaque_before(20.0));
        // A two-mesh fragment whose second part has not begun counts its first part only,
        // behind the same masks: still not opaque.
        let mut ab = ABuffer::new(16);
        for i in 0..12 {
            ab.insert(&pc(masked(1.0 + i as f32, 0.5, left)));
        }
        ab.insert(&pc(Frag { key: 1, ..masked(15.0, 0.5, left) }));
        ab.insert(&pc(Frag { key: 2, ..smp(15.3, 0.25, 1.0, Vec3::ONE) }));
        assert_eq!(ab.frags.len(), 13);
        assert!(!ab.opaque(15.0), "alpha {}", ab.alpha());
    }

    #[test]
    fn capacity_is_bounded() {
        let mut ab = ABuffer::new(4);
        for i in 0..20 {
            ab.insert(&pc(smp(i as f32, 0.1, 0.01, Vec3::ONE)));
        }
        assert!(ab.frags.len() <= 4);
        let w: f32 = ab.frags.iter().map(|f| f.w).sum();
        assert!((w - 0.2).abs() < 1e-5, "no weight is lost");
        for p in ab.frags.windows(2) {
            assert!(p[0].z1 < p[1].z0);
        }
    }

    fn piece(t: f32, d: f32, w: f32, c: Vec3, key: u32) -> Frag {
        Frag { z0: t - d, z1: t + d, w, wt: w * t, col: c * w, best_w: w, key, ..Default::default() }
    }

    /// `absorb`: a new mesh joins the group nearer in depth. Absorbing a two-mesh fragment
    /// (meshes 2 at t = 8 and 3 at 8.2) into a one-mesh fragment (mesh 1 at 5), mesh 3 must
    /// join mesh 2's group, not mesh 1's; the opaque red front then hides the blue behind it.
    /// (Review finding, stop 49: the comparison used the totals before `s` was added.)
    #[test]
    fn third_mesh_joins_the_nearer_group() {
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(piece(5.0, 0.1, 1.0, Vec3::X, 1)));
        ab.insert(&pc(piece(8.0, 0.5, 2.0, Vec3::Y, 2)));
        ab.insert(&pc(piece(8.2, 0.5, 1.0, Vec3::Z, 3)));
        assert_eq!(ab.frags.len(), 2);
        assert!(ab.frags[1].other.w > 0.0, "the second fragment holds two meshes");
        // A faint sample of mesh 1 bridges the two fragments: the first absorbs the second.
        ab.insert(&pc(piece(6.3, 1.25, 0.01, Vec3::X, 1)));
        assert_eq!(ab.frags.len(), 1);
        let (parts, n) = ab.frags[0].parts();
        assert_eq!(n, 2);
        assert!((parts[0].t() - 5.0).abs() < 0.1, "front part at mean depth {}, mesh 1 alone is at 5", parts[0].t());
        assert!((parts[1].t() - (8.0 * 2.0 + 8.2) / 3.0).abs() < 0.05, "back part at {}", parts[1].t());
        let mut o = Over::default();
        let col: Vec3 = parts[..n].iter().map(|p| p.col / p.w * o.add(p)).sum();
        assert!((col - Vec3::X).length() < 1e-3, "colour {col}: the blue behind bleeds into the opaque red front");
    }

    /// `opaque_before` counts only fragments that end before the front; one that was final
    /// and then grows past the front by a merge is not final any more. (Review finding, stop
    /// 49: only the final prefix's length was capped.)
    #[test]
    fn a_final_fragment_grown_past_the_front_is_not_final() {
        let mut ab = ABuffer::new(16);
        ab.insert(&pc(piece(1.5, 0.5, 0.6, Vec3::X, 0)));
        assert!(!ab.opaque_before(3.0));
        ab.insert(&pc(piece(3.45, 1.55, 0.6, Vec3::Y, 0)));
        assert_eq!(ab.frags.len(), 1);
        assert!(ab.frags[0].z1 > 3.0);
        assert!(!ab.opaque_before(3.0), "ended on the fragment [{}, {}], which reaches past the front 3", ab.frags[0].z0, ab.frags[0].z1);
        // Once the front passes it, it counts (alpha 1.2 → 1).
        assert!(ab.opaque_before(5.5));
    }
}
