//! On-disk cache of the point hierarchies (Wand & Straßer §3: the hierarchy is a
//! preprocessing step; the paper builds it once, offline). A built [`PointTree`] is written to
//! `cache_dir()/<key>.ptree` ([`crate::core::cache::cache_dir`], the same directory as the LOD
//! chains) and read back by later runs instead of being rebuilt.
//!
//! - Key: a 64-bit hash of everything the tree depends on — the mesh geometry (positions,
//!   normals, triangles), the materials the triangles use (colour and the seven shading
//!   properties, by value, in first-use order; names do not matter), every field of
//!   [`BuildParams`], [`FORMAT_VERSION`], the crate version and the text of the builder's
//!   source files (`build.rs`, `quant.rs`, this file, and the code they call: the tangent
//!   frame `core::onb` that ∇n is stored in, the random numbers of `core::rng` that place
//!   the samples, and `scene/mesh.rs`, whose triangle areas set the sample counts), so a
//!   changed builder never reads what an older one wrote. Bump [`FORMAT_VERSION`] when the layout changes all the same.
//! - Format: a compact little-endian binary image of the struct-of-arrays (no new dependency:
//!   the arrays are plain numbers, a dozen lines of writer/reader, like the LOD chain cache).
//!   Header: magic, format version, key, payload length and a checksum of the payload; then
//!   the tree's scalars, the node arrays, the point arrays and the triangle indices.
//! - Reading: any failure — a missing, truncated, corrupted or foreign file, a checksum or key
//!   mismatch, or an index out of range (child links must point forward, so a bad file can
//!   never make the traversal loop) — is a miss, and the tree is rebuilt silently and the file
//!   rewritten. Writing goes through a temporary file and a rename
//!   ([`crate::core::cache::write_atomic`]), so no reader sees a half-written file.
//! - A tree read back is bit-identical to the one built; its [`BuildStats::from_cache`] is set
//!   and its `seconds` is the read time.

use super::build::{build, BuildParams, BuildStats, MatRanges, NodeSoa, PointSoa, PointTree, NO_CHILD};
use super::quant::Range8;
use crate::core::cache::{cache_dir, write_atomic};
use crate::error::Result;
use crate::scene::{Material, Mesh};
use glam::Vec3;
use std::hash::Hasher;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Version of the cached layout *and* of the builder's output: bump on any change to either.
pub const FORMAT_VERSION: u32 = 7;
const MAGIC: [u8; 8] = *b"LTPTREE\0";
/// The source files whose code decides a tree's content, hashed into the key.
/// `core/mod.rs` holds [`crate::core::onb`], the frame ∇n is stored in and read back in
/// (stop 91: a changed frame used to read stale trees in the wrong frame).
const BUILDER_SOURCE: [&str; 6] = [
    include_str!("build.rs"),
    include_str!("quant.rs"),
    include_str!("cache.rs"),
    include_str!("../core/mod.rs"),
    include_str!("../core/rng.rs"),
    include_str!("../scene/mesh.rs"),
];
/// magic, version, key, payload length, checksum.
const HEADER: usize = 8 + 4 + 8 + 8 + 8;

/// [`build`] through the on-disk cache in [`cache_dir`] (built without a cache when there is
/// no usable cache directory).
pub fn cached(mesh: &Mesh, mats: &[&Material], params: &BuildParams) -> Result<PointTree> {
    cached_in(cache_dir().as_deref(), mesh, mats, params)
}

/// [`build`] through a cache in `dir` (None: no cache). Read failures rebuild; write failures
/// are ignored (the tree is still returned).
pub fn cached_in(dir: Option<&Path>, mesh: &Mesh, mats: &[&Material], params: &BuildParams) -> Result<PointTree> {
    params.validate()?;
    let Some(dir) = dir else { return build(mesh, mats, params) };
    if mats.len() != mesh.tri_count() {
        return build(mesh, mats, params); // its typed error
    }
    let t0 = Instant::now();
    let key = key(mesh, mats, params);
    let path = cache_path(dir, key);
    if let Some(mut t) = crate::core::cache::read_cache_file(&path).and_then(|b| decode(&b, key, mesh.tri_count(), params)) {
        t.tris = super::build::TriSoa::of(mesh, &t.tri_index);
        t.boxes = super::build::NodeBoxes::of(&t);
        t.stats.bytes = t.memory_bytes();
        t.stats.seconds = t0.elapsed().as_secs_f64();
        return Ok(t);
    }
    let t = build(mesh, mats, params)?;
    let _ = write_atomic(&path, &encode(&t, key));
    Ok(t)
}

/// The cache file of a key.
pub fn cache_path(dir: &Path, key: u64) -> PathBuf {
    dir.join(format!("{key:016x}.ptree"))
}

/// Cache key of the tree of (`mesh`, `mats`, `params`).
pub fn key(mesh: &Mesh, mats: &[&Material], params: &BuildParams) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    h.write(b"lodtrace-pointtree");
    h.write_u32(FORMAT_VERSION);
    h.write(env!("CARGO_PKG_VERSION").as_bytes());
    // The builder's own source: a changed build never reads a tree an older one wrote, even
    // when nobody bumped FORMAT_VERSION (stop 49 lost a fix to exactly that).
    for src in BUILDER_SOURCE {
        h.write(src.as_bytes());
    }
    let BuildParams { k, c, stay_reps, max_depth, seed, weights } = params; // every field (a new one fails to compile here)
    for x in [*k, c.to_bits(), *stay_reps, *max_depth, *seed, *weights as u32] {
        h.write_u32(x);
    }
    for v in [&mesh.px, &mesh.py, &mesh.pz, &mesh.nx, &mesh.ny, &mesh.nz] {
        hash_u32s(&mut h, v.len(), v.iter().map(|x| x.to_bits()));
    }
    hash_u32s(&mut h, mesh.tris.len() * 3, mesh.tris.iter().flatten().copied());
    // Materials by value, numbered in first-use order.
    let mut ids: std::collections::HashMap<[u32; 10], u32> = Default::default();
    let mut distinct: Vec<[u32; 10]> = Vec::new();
    let mut last: Option<(*const Material, u32)> = None;
    let per_tri: Vec<u32> = mats
        .iter()
        .map(|&m| match last {
            Some((p, id)) if std::ptr::eq(p, m) => id,
            _ => {
                let v = super::build::mat_props(m);
                let bits: [u32; 10] = std::array::from_fn(|i| if i < 3 { m.color[i].to_bits() } else { v[i - 3].to_bits() });
                let id = *ids.entry(bits).or_insert_with(|| {
                    distinct.push(bits);
                    (distinct.len() - 1) as u32
                });
                last = Some((m, id));
                id
            }
        })
        .collect();
    hash_u32s(&mut h, per_tri.len(), per_tri.iter().copied());
    hash_u32s(&mut h, distinct.len() * 10, distinct.iter().flatten().copied());
    h.finish()
}

/// Hashes a length and `n` words in blocks (one hasher call per 4 KiB, not per word).
fn hash_u32s(h: &mut impl Hasher, n: usize, it: impl Iterator<Item = u32>) {
    h.write_u64(n as u64);
    let mut buf = [0u8; 4096];
    let mut at = 0;
    for x in it {
        buf[at..at + 4].copy_from_slice(&x.to_le_bytes());
        at += 4;
        if at == buf.len() {
            h.write(&buf);
            at = 0;
        }
    }
    h.write(&buf[..at]);
}

fn checksum(b: &[u8]) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    h.write(b);
    h.finish()
}

// ---------------------------------------------------------------------------------------
// Writer and reader

#[derive(Default)]
struct W(Vec<u8>);

impl W {
    fn u32(&mut self, x: u32) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn u64(&mut self, x: u64) {
        self.0.extend_from_slice(&x.to_le_bytes());
    }
    fn f32(&mut self, x: f32) {
        self.u32(x.to_bits());
    }
    fn u8s(&mut self, v: &[u8]) {
        self.0.extend_from_slice(v);
    }
    fn u16s<'a>(&mut self, v: impl Iterator<Item = &'a u16>) {
        v.for_each(|x| self.0.extend_from_slice(&x.to_le_bytes()));
    }
    fn u32s(&mut self, v: &[u32]) {
        v.iter().for_each(|&x| self.u32(x));
    }
    fn f32s(&mut self, v: &[f32]) {
        v.iter().for_each(|&x| self.f32(x));
    }
}

struct R<'a> {
    b: &'a [u8],
    at: usize,
}

impl<'a> R<'a> {
    /// The next `n` bytes (checked against the remaining length before anything is allocated).
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.b.get(self.at..self.at.checked_add(n)?)?;
        self.at += n;
        Some(s)
    }
    fn u32(&mut self) -> Option<u32> {
        Some(u32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }
    fn u64(&mut self) -> Option<u64> {
        Some(u64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }
    fn f32(&mut self) -> Option<f32> {
        self.u32().map(f32::from_bits)
    }
    fn u8s(&mut self, n: usize) -> Option<Vec<u8>> {
        self.take(n).map(<[u8]>::to_vec)
    }
    fn arrays<const L: usize>(&mut self, n: usize) -> Option<Vec<[u8; L]>> {
        Some(self.take(n.checked_mul(L)?)?.chunks_exact(L).map(|c| c.try_into().expect("L bytes")).collect())
    }
    fn u16_arrays<const L: usize>(&mut self, n: usize) -> Option<Vec<[u16; L]>> {
        let b = self.take(n.checked_mul(2 * L)?)?;
        Some(b.chunks_exact(2 * L).map(|c| std::array::from_fn(|i| u16::from_le_bytes([c[2 * i], c[2 * i + 1]]))).collect())
    }
    fn u32s(&mut self, n: usize) -> Option<Vec<u32>> {
        Some(self.take(n.checked_mul(4)?)?.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().expect("4 bytes"))).collect())
    }
    fn f32s(&mut self, n: usize) -> Option<Vec<f32>> {
        Some(self.u32s(n)?.into_iter().map(f32::from_bits).collect())
    }
}

/// The cache file image of `t` under `key`.
pub fn encode(t: &PointTree, key: u64) -> Vec<u8> {
    let mut w = W::default();
    w.f32(t.root_side);
    w.u32(t.k);
    w.f32(t.ranges.color_hi);
    for r in &t.ranges.props {
        w.f32(r.lo);
        w.f32(r.hi);
        w.u32(r.log as u32);
    }
    w.u64(t.stats.triangles_dropped as u64);
    w.u64(t.stats.samples);
    w.u32(t.stats.max_depth);
    let n = &t.nodes;
    w.u32(n.len() as u32);
    for v in [&n.cx, &n.cy, &n.cz, &n.r] {
        w.f32s(v);
    }
    w.u32s(&n.first_child);
    w.u8s(&n.depth);
    n.grid_lo.iter().for_each(|g| w.f32s(&g.to_array()));
    for v in [&n.pt_start, &n.pt_count, &n.tri_start, &n.tri_count] {
        w.u32s(v);
    }
    let p = &t.points;
    w.u32(p.len() as u32);
    for v in [&p.qx, &p.qy, &p.qz] {
        w.u8s(v);
    }
    w.u16s(p.normal.iter().flatten());
    w.u8s(&p.cover);
    w.u8s(&p.nlen);
    p.rgb.iter().for_each(|c| w.u8s(c));
    p.mat.iter().for_each(|m| w.u8s(m));
    w.u16s(p.grad.iter().flatten());
    w.u32(t.tri_index.len() as u32);
    w.u32s(&t.tri_index);

    let payload = w.0;
    let mut out = Vec::with_capacity(HEADER + payload.len());
    out.extend_from_slice(&MAGIC);
    out.extend_from_slice(&FORMAT_VERSION.to_le_bytes());
    out.extend_from_slice(&key.to_le_bytes());
    out.extend_from_slice(&(payload.len() as u64).to_le_bytes());
    out.extend_from_slice(&checksum(&payload).to_le_bytes());
    out.extend_from_slice(&payload);
    out
}

/// Reads a cache file image; None on any inconsistency with `key`, the mesh's triangle count
/// `n_tris` or `params` (then the tree is rebuilt).
pub fn decode(b: &[u8], key: u64, n_tris: usize, params: &BuildParams) -> Option<PointTree> {
    let mut r = R { b, at: 0 };
    if r.take(8)? != MAGIC || r.u32()? != FORMAT_VERSION || r.u64()? != key {
        return None;
    }
    let len = r.u64()?;
    let sum = r.u64()?;
    if len != (b.len() - HEADER) as u64 || checksum(&b[HEADER..]) != sum {
        return None;
    }
    let root_side = r.f32()?;
    let k = r.u32()?;
    let color_hi = r.f32()?;
    let mut props = [Range8::default(); 7];
    for p in &mut props {
        *p = Range8 { lo: r.f32()?, hi: r.f32()?, log: r.u32()? != 0 };
    }
    let triangles_dropped = r.u64()? as usize;
    let samples = r.u64()?;
    let max_depth = r.u32()?;
    if k != params.k || !(root_side.is_finite() && root_side > 0.0) || max_depth > params.max_depth {
        return None;
    }

    let nn = r.u32()? as usize;
    let mut nodes = NodeSoa { cx: r.f32s(nn)?, cy: r.f32s(nn)?, cz: r.f32s(nn)?, r: r.f32s(nn)?, ..Default::default() };
    nodes.first_child = r.u32s(nn)?;
    nodes.depth = r.u8s(nn)?;
    nodes.grid_lo = r.f32s(nn.checked_mul(3)?)?.chunks_exact(3).map(Vec3::from_slice).collect();
    nodes.pt_start = r.u32s(nn)?;
    nodes.pt_count = r.u32s(nn)?;
    nodes.tri_start = r.u32s(nn)?;
    nodes.tri_count = r.u32s(nn)?;

    let np = r.u32()? as usize;
    let points = PointSoa {
        qx: r.u8s(np)?,
        qy: r.u8s(np)?,
        qz: r.u8s(np)?,
        normal: r.u16_arrays::<2>(np)?,
        cover: r.u8s(np)?,
        nlen: r.u8s(np)?,
        rgb: r.arrays::<3>(np)?,
        mat: r.arrays::<7>(np)?,
        grad: r.u16_arrays::<4>(np)?,
    };
    let nt = r.u32()? as usize;
    let tri_index = r.u32s(nt)?;
    if r.at != b.len() {
        return None;
    }

    // Structure: everything the traversal indexes must be in range, child links point forward.
    if nn == 0 || tri_index.iter().any(|&t| t as usize >= n_tris) {
        return None;
    }
    for i in 0..nn {
        let fc = nodes.first_child[i];
        if fc != NO_CHILD && !(fc as usize > i && fc as usize + 8 <= nn) {
            return None;
        }
        if nodes.depth[i] as u32 > max_depth
            || nodes.pt_start[i] as u64 + nodes.pt_count[i] as u64 > np as u64
            || nodes.tri_start[i] as u64 + nodes.tri_count[i] as u64 > nt as u64
        {
            return None;
        }
    }
    // Values: every float finite (a forged file with a NaN sphere or range was trusted before
    // stop 57; the builder never writes one), radii ≥ 0 or −∞ (an empty child slot, which no
    // cone hits), ranges ordered.
    let fin = |v: &[f32]| v.iter().all(|x| x.is_finite());
    let radius = |r: f32| (r.is_finite() && r >= 0.0) || r == f32::NEG_INFINITY;
    if !(fin(&nodes.cx)
        && fin(&nodes.cy)
        && fin(&nodes.cz)
        && nodes.r.iter().all(|&r| radius(r))
        && nodes.grid_lo.iter().all(|p| p.is_finite()))
        || !(color_hi.is_finite() && props.iter().all(|p| p.lo.is_finite() && p.hi.is_finite() && p.lo <= p.hi && (!p.log || p.lo > 0.0)))
    {
        return None;
    }
    let g = 2 * k * super::build::codes_per_voxel(k); // position codes per axis, margin included
    if points.qx.iter().chain(&points.qy).chain(&points.qz).any(|&q| q as u32 >= g) {
        return None;
    }

    let mut t = PointTree {
        nodes,
        points,
        tri_index,
        root_side,
        k,
        ranges: MatRanges { color_hi, props },
        stats: BuildStats { triangles_dropped, samples, max_depth, from_cache: true, ..Default::default() },
        tris: Default::default(),  // derived from the mesh by the caller
        boxes: Default::default(), // likewise
        levels: super::build::Levels::of(root_side, k),
        mat: super::build::MatTable::of(&MatRanges { color_hi, props }),
    };
    t.stats.nodes = t.nodes.len();
    t.stats.points = t.points.len();
    t.stats.triangles_stored = t.tri_index.len();
    t.stats.bytes = t.memory_bytes();
    Some(t)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin;

    /// A fresh cache directory per test (tests run in parallel; no process env is touched).
    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("lodtrace-ptree-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn same(a: &PointTree, b: &PointTree) {
        assert_eq!(a.nodes, b.nodes);
        assert_eq!(a.points, b.points);
        assert_eq!(a.tri_index, b.tri_index);
        assert_eq!((a.root_side.to_bits(), a.k), (b.root_side.to_bits(), b.k));
        assert_eq!(a.ranges, b.ranges);
        // Derived after the read: the same node boxes.
        assert_eq!((&a.boxes.lo, &a.boxes.hi), (&b.boxes.lo, &b.boxes.hi));
        let s = |t: &PointTree| {
            let s = &t.stats;
            (s.nodes, s.points, s.triangles_stored, s.triangles_dropped, s.samples, s.max_depth, s.bytes)
        };
        assert_eq!(s(a), s(b));
    }

    fn scene() -> (Mesh, Vec<Material>) {
        let mut mesh = builtin::checkerboard(8, 2.0, 0, 1);
        mesh.compute_normals();
        (mesh, vec![Material::diffuse("w", Vec3::ONE), Material::diffuse("b", Vec3::new(0.1, 0.2, 0.3))])
    }

    #[test]
    fn tree_round_trips_through_the_cache_and_bad_files_are_rebuilt() {
        let dir = temp_dir("roundtrip");
        let (mesh, ms) = scene();
        let mats: Vec<&Material> = mesh.mat.iter().map(|&m| &ms[m as usize]).collect();
        let p = BuildParams::default();
        let fresh = build(&mesh, &mats, &p).unwrap();
        assert!(!fresh.stats.from_cache);

        // First run builds and writes, the second reads back the same tree.
        let a = cached_in(Some(&dir), &mesh, &mats, &p).unwrap();
        assert!(!a.stats.from_cache);
        let path = cache_path(&dir, key(&mesh, &mats, &p));
        let good = std::fs::read(&path).expect("cache file written");
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 1, "only the cache file, no temporary");
        let b = cached_in(Some(&dir), &mesh, &mats, &p).unwrap();
        assert!(b.stats.from_cache);
        same(&fresh, &a);
        same(&fresh, &b);

        // Truncated, bit-flipped, empty and foreign files are rejected, rebuilt and rewritten.
        let mut flipped = good.clone();
        let mid = HEADER + (good.len() - HEADER) / 2;
        flipped[mid] ^= 0x10;
        let mut bad_len = good.clone();
        bad_len.push(0);
        for bad in [good[..good.len() - 5].to_vec(), good[..HEADER + 3].to_vec(), flipped, bad_len, vec![], b"not a tree".to_vec()] {
            assert!(decode(&bad, key(&mesh, &mats, &p), mesh.tri_count(), &p).is_none());
            std::fs::write(&path, &bad).unwrap();
            let t = cached_in(Some(&dir), &mesh, &mats, &p).unwrap();
            assert!(!t.stats.from_cache, "a bad file was accepted");
            same(&fresh, &t);
            assert_eq!(std::fs::read(&path).unwrap(), good, "the file is rewritten");
            assert!(cached_in(Some(&dir), &mesh, &mats, &p).unwrap().stats.from_cache);
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A well-formed file (valid checksum) whose indices are out of range is still rejected.
    #[test]
    fn inconsistent_trees_are_rejected_even_with_a_valid_checksum() {
        let (mesh, ms) = scene();
        let mats: Vec<&Material> = mesh.mat.iter().map(|&m| &ms[m as usize]).collect();
        let p = BuildParams::default();
        let t = build(&mesh, &mats, &p).unwrap();
        let key = key(&mesh, &mats, &p);
        assert!(decode(&encode(&t, key), key, mesh.tri_count(), &p).is_some());
        assert!(decode(&encode(&t, key), key ^ 1, mesh.tri_count(), &p).is_none(), "foreign key");
        assert!(decode(&encode(&t, key), key, mesh.tri_count() - 1, &p).is_none(), "triangle index out of range");
        assert!(decode(&encode(&t, key), key, mesh.tri_count(), &BuildParams { k: 8, ..p.clone() }).is_none());
        let mut bad = t.clone();
        bad.nodes.first_child[0] = 0; // a cycle
        assert!(decode(&encode(&bad, key), key, mesh.tri_count(), &p).is_none());
        let mut bad = t.clone();
        let last = bad.nodes.len() - 1;
        bad.nodes.pt_count[last] = bad.points.len() as u32 + 1;
        assert!(decode(&encode(&bad, key), key, mesh.tri_count(), &p).is_none());
        // Non-finite values with a valid checksum (stop 57).
        let mut bad = t.clone();
        bad.nodes.r[last] = f32::NAN;
        assert!(decode(&encode(&bad, key), key, mesh.tri_count(), &p).is_none(), "NaN radius");
        let mut bad = t.clone();
        bad.nodes.cx[0] = f32::INFINITY;
        assert!(decode(&encode(&bad, key), key, mesh.tri_count(), &p).is_none(), "infinite centre");
        let mut bad = t.clone();
        bad.ranges.props[2].hi = f32::NAN;
        assert!(decode(&encode(&bad, key), key, mesh.tri_count(), &p).is_none(), "NaN property range");
    }

    /// The whole scene (instances with material overrides): the second build reads every tree
    /// back, and the image rendered from them is bit-identical.
    #[test]
    fn scene_from_the_cache_renders_the_same_image() {
        use super::super::render::render;
        use super::super::trace::{MultiresScene, TraceParams};
        use crate::baseline::render::RenderOpts;
        let dir = temp_dir("scene");
        let scene = builtin::get("instanced").unwrap();
        let bp = BuildParams::default();
        let (w, h) = (48, 36);
        let opts = RenderOpts { width: w, height: h, quiet: true, ..Default::default() };
        let img = |ms: &MultiresScene| render(ms, &TraceParams::default(), &scene.camera.frame(w, h), &opts).unwrap().out.film;
        let a = MultiresScene::build_in(&scene, &bp, Some(&dir)).unwrap();
        assert!(a.trees.len() > 1, "the scene should have several trees");
        assert_eq!(a.trees_from_cache(), 0);
        let b = MultiresScene::build_in(&scene, &bp, Some(&dir)).unwrap();
        assert_eq!(b.trees_from_cache(), b.trees.len());
        for (x, y) in a.trees.iter().zip(&b.trees) {
            same(x, y);
        }
        let (fa, fb) = (img(&a), img(&b));
        assert!(fa.color.iter().zip(&fb.color).all(|(x, y)| x.to_array().map(f32::to_bits) == y.to_array().map(f32::to_bits)));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn key_covers_geometry_materials_and_params() {
        let (mesh, ms) = scene();
        let mats: Vec<&Material> = mesh.mat.iter().map(|&m| &ms[m as usize]).collect();
        let p = BuildParams::default();
        let k0 = key(&mesh, &mats, &p);
        // Equal materials at other addresses: same key (names do not matter either).
        let copies: Vec<Material> = ms.iter().map(|m| Material { name: "other".into(), ..m.clone() }).collect();
        let mats2: Vec<&Material> = mesh.mat.iter().map(|&m| &copies[m as usize]).collect();
        assert_eq!(key(&mesh, &mats2, &p), k0);
        // Swapped materials, a changed property, moved geometry, other params: other keys.
        let swapped: Vec<&Material> = mesh.mat.iter().map(|&m| &ms[1 - m as usize]).collect();
        assert_ne!(key(&mesh, &swapped, &p), k0);
        let shiny = Material { ks: 0.5, ..ms[0].clone() };
        let mats3: Vec<&Material> = mesh.mat.iter().map(|&m| if m == 0 { &shiny } else { &ms[1] }).collect();
        assert_ne!(key(&mesh, &mats3, &p), k0);
        let mut moved = mesh.clone();
        moved.px[0] += 1e-6;
        assert_ne!(key(&moved, &mats, &p), k0);
        assert_ne!(key(&mesh, &mats, &BuildParams { seed: 1, ..p.clone() }), k0);
        assert_ne!(key(&mesh, &mats, &BuildParams { c: 50.0, ..p.clone() }), k0);
    }

    /// The code a stored tree depends on beyond the builder's own files is hashed into the
    /// key too: the tangent frame ∇n is stored in (and read back in by the renderer), the
    /// sampler that places the samples and the triangle areas that set their counts.
    #[test]
    fn key_covers_the_code_the_tree_depends_on() {
        for f in ["pub fn onb(", "pub fn pcg_hash(", "pub struct Sampler", "pub fn tri_cross("] {
            assert!(BUILDER_SOURCE.iter().any(|s| s.contains(f)), "{f} is not in the hashed sources");
        }
    }
}
