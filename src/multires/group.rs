//! Instance-level points: prefiltered representative points over whole groups of instances,
//! one point set per inner slot of the instance tree ([`super::trace::Tlas`]).
//!
//! *A completion the paper leaves open.* Wand & Straßer build the point hierarchy per object
//! (§3) and render `complex` from a scene graph with hierarchical instantiation (§6, 8.7 M
//! instanced of 110 k unique triangles), but do not say how the level of detail continues
//! above the objects. Without it a cone wider than a whole instance still visits every
//! instance it overlaps: on `complex` the reflected and refracted cones of the chrome cows
//! and glass bunnies reached 35 instance roots each, and 80% of those roots were already
//! 8–128 times finer than the cone's footprint (measured at 640×480: 3.9 M root visits that
//! went straight to the root's points). Here the §3 construction is applied once more, over
//! each slot of the instance tree: a grid over the slot's bounding cube (spacing h = cube
//! side / 2k), random surface samples of every instance below it at c per h² (the paper's
//! oversampling factor; the grid is 2k voxels wide, `GRID_FACTOR`), and per occupied voxel
//! one representative with the area-weighted average colour, material and normal, the normal
//! spread (|mean normal|) and the sampled area (`cover`, the `area` point weight of
//! [`super::build::PointWeights`]). The traversal uses a
//! slot's points exactly as an octree node's (§5.1): when lod_scale·σ_min ≥ h at the slot,
//! with the mipmap blend one level down. The level below is what the traversal chooses below
//! the slot for the same footprint (stop 82): a child slot or instance root need not have half
//! the slot's spacing, as an octree child has.
//!
//! Deviations from the per-object build ([`super::build`]), written down here:
//! - Samples come from a fixed random sample list per hierarchy (16 k samples, drawn in
//!   object space, area-uniform) transformed into world space per instance; an instance uses
//!   the first ⌈c·A/h²⌉ of them (all of them when it would need more), each standing for
//!   A / n of the instance's world area A (object area × |det|^(2/3), exact for similarity
//!   transforms). The list starts at a per-instance offset, so instances of one mesh are not
//!   sampled alike.
//! - Averages are box-filtered over the voxel instead of the Gaussian of σ = one voxel, and
//!   ∇n is zero (the aggregate is shaded flat; secondary cones from it spread by their
//!   footprint only). These points stand for whole groups of objects, seen only by cones
//!   much wider than the objects.
//! - A point sits at the area-weighted mean position of its samples, in 8 bits per axis over
//!   the slot's cube (the paper's 8-bit positions), not at its voxel centre as in the
//!   per-object build: a slot's voxels are large (its cube is as wide as its widest side), and
//!   a flat group of tiles lies on a voxel boundary, so centres would lift it by h/2
//!   (measured: 8% too bright under a point light at 40 units, tiles 2 units per voxel).

use super::build::{mat_props, sample_triangle, BuildParams, MatRanges, PointSoa};
use super::quant;
use super::trace::{MLeaf, Tlas, LEAF};
use crate::core::rng::{pcg_hash, Sampler};
use crate::scene::{Material, Mesh};
use glam::{Mat3, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;
use std::hash::BuildHasherDefault;

/// A slot's grid has `GRID_FACTOR`·k voxels per side. A slot's cube is as wide as its widest
/// side, and most slots are flat (tiles of the floor, fields of plants), so its voxels are
/// coarse where an octree node's are not. `complex` 640×480 (one run): k voxels 2.52 s,
/// 2k 2.35 s (59 k points, 0.09 s to build), 4k 2.29 s (227 k points, 0.30 s); mean FLIP
/// 0.1193, 0.1191, 0.1188.
const GRID_FACTOR: usize = 2;

/// Samples per hierarchy in its object-space list.
const LIST: usize = 1 << 14;

/// The instance-level points of a scene: per `Tlas` slot a range of `points` (empty for
/// leaf and empty slots), its grid origin and spacing.
#[derive(Clone, Debug, Default)]
pub struct GroupPoints {
    pub start: Vec<u32>,
    pub count: Vec<u32>,
    pub grid_lo: Vec<Vec3>,
    /// Point spacing of the slot (0: no points).
    pub h: Vec<f32>,
    /// Step of the 8-bit point positions: a point is at `grid_lo + (q + ½)·step`.
    pub step: Vec<f32>,
    /// The box of each slot's point codes, as [`super::build::NodeBoxes::pts`].
    pub pts_box: Vec<[u8; 6]>,
    pub points: PointSoa,
    /// Material code ranges over all the scene's materials.
    pub ranges: MatRanges,
    /// `ranges` decoded ([`super::build::MatTable`]).
    pub mat: super::build::MatTable,
    /// Samples drawn (all slots).
    pub samples: u64,
}

impl GroupPoints {
    pub fn bytes(&self) -> usize {
        self.start.len() * (4 + 4 + 12 + 4 + 4 + 6) + self.points.bytes()
    }
}

/// An object-space sample list of one hierarchy.
struct SampleList {
    p: Vec<Vec3>,
    n: Vec<Vec3>,
    /// Index into the scene's materials.
    mat: Vec<u32>,
    /// Object-space surface area of the mesh.
    area: f32,
}

fn sample_list(mesh: &Mesh, mat_of: impl Fn(usize) -> u32, seed: u32) -> SampleList {
    let mut cdf = Vec::with_capacity(mesh.tri_count());
    let mut total = 0.0f64;
    for t in 0..mesh.tri_count() {
        let [a, b, c] = mesh.tri_verts(t);
        // In f64, as the octree build takes them (`build::build`): the f32 cross product's
        // length overflows for edges past ~4e9, and a mesh of such triangles got no
        // instance-level points (review finding, stop 91).
        let ar = 0.5 * mesh.tri_cross(t).length();
        if ar.is_finite() && ar > 0.0 && a.is_finite() && b.is_finite() && c.is_finite() {
            total += ar;
        }
        cdf.push(total);
    }
    let mut l = SampleList { p: Vec::new(), n: Vec::new(), mat: Vec::new(), area: total as f32 };
    if !(total > 0.0) {
        return l;
    }
    for s in 0..LIST as u32 {
        let mut r = Sampler::new(seed, 0x6a09_e667, s);
        let x = r.next() as f64 * total;
        let t = cdf.partition_point(|&c| c <= x).min(cdf.len() - 1);
        let [i0, i1, i2] = mesh.tris[t];
        let (a, b, c) = (mesh.pos(i0), mesh.pos(i1), mesh.pos(i2));
        let (u, v) = r.next2();
        let (w0, w1, w2) = sample_triangle(u, v);
        let ng = mesh.tri_cross(t).normalize_or_zero().as_vec3();
        let mut n = (mesh.normal(i0) * w0 + mesh.normal(i1) * w1 + mesh.normal(i2) * w2).normalize_or_zero();
        if n == Vec3::ZERO || !n.is_finite() {
            n = ng;
        }
        l.p.push(a * w0 + b * w1 + c * w2);
        l.n.push(n);
        l.mat.push(mat_of(t));
    }
    l
}

/// The voxel map's hasher. A key is a voxel index (`u32`); one multiply by 2^64/φ spreads it
/// over the high bits, which are folded onto the low ones that pick the bucket. SipHash, the
/// standard map's default, guards against keys chosen by an adversary, which these are not;
/// it took about 0.9 G of the 1.4 G instructions of [`build`] on `complex` (callgrind, stop
/// 82). The points come out the same: each voxel still sums its samples in their order, and
/// the voxels are sorted after.
#[derive(Default)]
struct CellHasher(u64);

impl std::hash::Hasher for CellHasher {
    fn finish(&self) -> u64 {
        self.0 ^ (self.0 >> 32)
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u32(b as u32);
        }
    }
    fn write_u32(&mut self, v: u32) {
        self.0 = (self.0 ^ v as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15);
    }
}

#[derive(Clone, Copy, Default)]
struct Acc {
    area: f32,
    pos: Vec3,
    col: Vec3,
    props: [f32; 7],
    n: Vec3,
}

/// Builds the points of every inner slot of `tlas`. `tree_mats(tree)` gives the mesh and the
/// per-triangle material of each hierarchy.
pub fn build(materials: &[Material], tree_meshes: &[(&Mesh, Vec<u32>)], leaves: &[MLeaf], tlas: &Tlas, bp: &BuildParams) -> GroupPoints {
    let lists: Vec<SampleList> = tree_meshes
        .par_iter()
        .enumerate()
        .map(|(i, (mesh, mats))| sample_list(mesh, |t| mats[t], pcg_hash(bp.seed ^ (i as u32).wrapping_mul(0x9e37_79b9))))
        .collect();
    let all: Vec<&Material> = materials.iter().collect();
    let ranges = MatRanges::of(&all);
    let slots = tlas.r.len();
    // The leaves below each slot, gathered bottom-up (children come after their parent).
    let mut below: Vec<Vec<u32>> = vec![Vec::new(); slots];
    for s in (0..slots).rev() {
        if tlas.r[s] < 0.0 {
            continue;
        }
        let ch = tlas.child[s];
        if ch & LEAF != 0 {
            below[s].push(ch & !LEAF);
        } else {
            let mut v = Vec::new();
            for b in &below[ch as usize..ch as usize + 8] {
                v.extend_from_slice(b);
            }
            below[s] = v;
        }
    }
    let k = bp.k as usize * GRID_FACTOR;
    let built: Vec<(Vec3, f32, f32, Vec<RawGroupPoint>, u64)> = (0..slots)
        .into_par_iter()
        .map(|s| {
            if tlas.r[s] < 0.0 || tlas.child[s] & LEAF != 0 {
                return (Vec3::ZERO, 0.0, 0.0, Vec::new(), 0);
            }
            let lo = Vec3::new(tlas.lo[0][s], tlas.lo[1][s], tlas.lo[2][s]);
            let hi = Vec3::new(tlas.hi[0][s], tlas.hi[1][s], tlas.hi[2][s]);
            let side = (hi - lo).max_element().max(1e-6) * 1.001;
            let h = side / k as f32;
            let step = side / 256.0;
            let grid_lo = (lo + hi) * 0.5 - Vec3::splat(side * 0.5);
            let mut cells: HashMap<u32, Acc, BuildHasherDefault<CellHasher>> = HashMap::default();
            let mut drawn = 0u64;
            for &li in &below[s] {
                let leaf = &leaves[li as usize];
                let l = &lists[leaf.tree as usize];
                if l.p.is_empty() {
                    continue;
                }
                let m3 = Mat3::from(leaf.xform.matrix3);
                let a_world = l.area * m3.determinant().abs().powf(2.0 / 3.0);
                if !(a_world > 0.0 && a_world.is_finite()) {
                    continue;
                }
                let want = (bp.c * a_world / (h * h)).ceil();
                let n = if want >= l.p.len() as f32 { l.p.len() } else { (want as usize).max(1) };
                let da = a_world / n as f32;
                let off = pcg_hash(li ^ 0x5bd1_e995) as usize % l.p.len();
                for j in 0..n {
                    let i = (off + j) % l.p.len();
                    let p = leaf.xform.transform_point3(l.p[i]);
                    let nn = (leaf.normal_mat * l.n[i]).normalize_or_zero();
                    let q = ((p - grid_lo) / h).floor();
                    let c = |v: f32| (v as i32).clamp(0, k as i32 - 1) as u32;
                    let cell = (c(q.z) * k as u32 + c(q.y)) * k as u32 + c(q.x);
                    let m = &materials[l.mat[i] as usize];
                    let a = cells.entry(cell).or_default();
                    a.area += da;
                    a.pos += p * da;
                    a.col += m.color * da;
                    for (x, v) in a.props.iter_mut().zip(mat_props(m)) {
                        *x += v * da;
                    }
                    a.n += nn * da;
                }
                drawn += n as u64;
            }
            let mut pts: Vec<RawGroupPoint> = cells
                .into_iter()
                .filter(|(_, a)| a.area > 0.0)
                .map(|(cell, a)| {
                    let inv = 1.0 / a.area;
                    let nav = if a.n.length_squared() > 1e-12 * a.area * a.area { a.n.normalize() } else { Vec3::Y };
                    let q = ((a.pos * inv - grid_lo) / step).floor().clamp(Vec3::ZERO, Vec3::splat(255.0));
                    let g = [q.x as u8, q.y as u8, q.z as u8];
                    RawGroupPoint {
                        cell,
                        g,
                        normal: quant::oct_encode(nav),
                        cover: quant::encode_cover_dithered(a.area / (h * h), quant::unit_of_hash(pcg_hash(s as u32 ^ pcg_hash(cell)))),
                        nlen: quant::encode_unit(a.n.length() * inv),
                        rgb: [a.col.x, a.col.y, a.col.z].map(|v| quant::encode_color(v * inv, ranges.color_hi)),
                        mat: std::array::from_fn(|i| ranges.props[i].encode(a.props[i] * inv)),
                    }
                })
                .collect();
            // Deterministic order (the hash map's is not).
            pts.sort_unstable_by_key(|p| p.cell);
            (grid_lo, h, step, pts, drawn)
        })
        .collect();
    let mut g = GroupPoints { mat: super::build::MatTable::of(&ranges), ranges, ..Default::default() };
    for (grid_lo, h, step, pts, drawn) in built {
        g.start.push(g.points.len() as u32);
        g.count.push(pts.len() as u32);
        g.grid_lo.push(grid_lo);
        g.h.push(if pts.is_empty() { 0.0 } else { h });
        g.step.push(step);
        g.samples += drawn;
        let (lo, hi) = pts.iter().fold(([u8::MAX; 3], [0u8; 3]), |(lo, hi), r| {
            (std::array::from_fn(|k| lo[k].min(r.g[k])), std::array::from_fn(|k| hi[k].max(r.g[k])))
        });
        g.pts_box.push(if pts.is_empty() { [0; 6] } else { [lo[0], lo[1], lo[2], hi[0], hi[1], hi[2]] });
        let p = &mut g.points;
        for r in pts {
            p.qx.push(r.g[0]);
            p.qy.push(r.g[1]);
            p.qz.push(r.g[2]);
            p.normal.push(r.normal);
            p.cover.push(r.cover);
            p.nlen.push(r.nlen);
            p.rgb.push(r.rgb);
            p.mat.push(r.mat);
            p.grad.push([0; 4]);
        }
    }
    g
}

struct RawGroupPoint {
    cell: u32,
    g: [u8; 3],
    normal: [u16; 2],
    cover: u8,
    nlen: u8,
    rgb: [u8; 3],
    mat: [u8; 7],
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::multires::trace::MultiresScene;
    use crate::scene::{builtin, Scene, Target};
    use glam::Affine3A;

    /// A floor of n×n instanced unit tiles, every other one scaled by 1.5 (and lifted out of
    /// the way): the points of each slot stand for the world area of the instances below it.
    fn tiles(n: i32) -> Scene {
        tiles_of_side(n, 1.0)
    }

    /// [`tiles`] with tiles (and their spacing) of side `side`.
    fn tiles_of_side(n: i32, side: f32) -> Scene {
        let mut s = Scene::empty("tiles");
        let tile = s.add_mesh(builtin::checkerboard(4, side, 0, 0));
        for i in 0..n {
            for j in 0..n {
                let sc = if (i + j) % 2 == 0 { 1.0 } else { 1.5 };
                let at = Vec3::new(i as f32 * 2.0, ((i * 7 + j * 3) % 5) as f32 * 0.3, j as f32 * 2.0) * side;
                let xf = Affine3A::from_translation(at) * Affine3A::from_scale(Vec3::splat(sc));
                s.instance(Target::Mesh(tile), xf, None);
            }
        }
        s.validate().unwrap();
        s
    }

    #[test]
    fn slot_points_hold_the_area_below_them() {
        let scene = tiles(12);
        let ms = MultiresScene::build_in(&scene, &BuildParams::default(), None).unwrap();
        let (g, tl) = (&ms.groups, &ms.tlas);
        let area = |li: u32| {
            let s = ms.leaves[li as usize].xform.matrix3.x_axis.length();
            s * s
        };
        fn leaves_below(tl: &Tlas, s: usize, out: &mut Vec<u32>) {
            let ch = tl.child[s];
            if tl.r[s] < 0.0 {
            } else if ch & LEAF != 0 {
                out.push(ch & !LEAF);
            } else {
                for c in ch as usize..ch as usize + 8 {
                    leaves_below(tl, c, out);
                }
            }
        }
        let mut checked = 0;
        for s in 0..tl.r.len() {
            if g.count[s] == 0 {
                continue;
            }
            let mut below = vec![];
            leaves_below(tl, s, &mut below);
            let want: f32 = below.iter().map(|&l| area(l)).sum();
            let (a, b) = (g.start[s] as usize, (g.start[s] + g.count[s]) as usize);
            let h = g.h[s];
            let got: f32 = g.points.cover[a..b].iter().map(|&c| quant::decode_cover(c) * h * h).sum();
            // Cover codes step by 1/64 of h² per point.
            let tol = 0.02 * want + (b - a) as f32 * h * h / 128.0;
            assert!((got - want).abs() <= tol, "slot {s}: points hold {got}, instances {want} (± {tol})");
            // Every point lies in the slot's box (up to half a voxel: centres of the cells), and
            // its codes in the slot's code box, which they span.
            let qb = g.pts_box[s];
            for (k, q) in [&g.points.qx, &g.points.qy, &g.points.qz].into_iter().enumerate() {
                assert_eq!((q[a..b].iter().min(), q[a..b].iter().max()), (Some(&qb[k]), Some(&qb[k + 3])), "slot {s} axis {k}");
            }
            for i in a..b {
                let st = g.step[s];
                let p = g.grid_lo[s] + (Vec3::new(g.points.qx[i] as f32, g.points.qy[i] as f32, g.points.qz[i] as f32) + 0.5) * st;
                for k in 0..3 {
                    assert!(p[k] >= tl.lo[k][s] - 0.5 * st && p[k] <= tl.hi[k][s] + 0.5 * st, "point {p} outside slot {s}");
                }
                assert!((quant::oct_decode(g.points.normal[i]).y - 1.0).abs() < 1e-3, "tiles face +y");
            }
            checked += 1;
        }
        assert!(checked >= 10, "{checked} slots with points");
        // Deterministic: the same points on a second build.
        let again = MultiresScene::build_in(&scene, &BuildParams::default(), None).unwrap();
        assert_eq!(again.groups.points, ms.groups.points);
    }

    /// Tiles whose cells are 5e9 units wide get their slots' points as unit tiles do: the
    /// sample list takes the triangle areas in f64 (the f32 cross product's length
    /// overflowed, every area came out infinite and the slots got no points; stop 91).
    #[test]
    fn huge_instances_get_slot_points() {
        let slots_with_points = |side: f32| {
            let scene = tiles_of_side(6, side);
            let ms = MultiresScene::build_in(&scene, &BuildParams::default(), None).unwrap();
            ms.groups.count.iter().filter(|&&c| c > 0).count()
        };
        let unit = slots_with_points(1.0);
        assert!(unit > 0);
        assert_eq!(slots_with_points(2e10), unit);
    }
}
