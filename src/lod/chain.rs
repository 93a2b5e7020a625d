//! LOD chains (Papaioannou et al. §2): every unique mesh at up to eight resolutions,
//! `L_0` the original, and the per-level scenes the tracer intersects.
//!
//! The paper normalises the level of detail to LOD ∈ [0, 1] ("a 0.5 model quality means
//! that the desired resolution mesh must have at least half the polygons of the original")
//! and selects model `k = lvl_max − ⌈LOD · lvl_max⌉` ([`level_of`]). So level k must keep at
//! least the fraction `(lvl_max − k)/lvl_max` of the triangles: the chain is *linear* in the
//! triangle count ([`level_fraction`]). The last level (LOD = 0 exactly) would have no
//! triangles; it keeps `1/(2·lvl_max)` instead (a documented floor).
//!
//! Simplification: meshoptimizer's quadric edge collapse (`meshopt::simplify`), per material
//! group with locked borders so that groups stay stitched; when the topology stops edge
//! collapse short of the target, the result is kept (it has *more* triangles than asked,
//! which the "at least" of the paper allows). Meshes too small to simplify (fewer than
//! [`MIN_TRIANGLES`]) keep the original at every level (documented fallback). Each level
//! keeps only the vertices it uses, with the original normals.
//!
//! The paper's 2003 chains were "generated externally with the help of commercial
//! software"; they are built here once per unique mesh, in parallel (rayon), shared by all
//! instances, and cached on disk ([`cache_dir`], keyed by a hash of the mesh), so later runs
//! read them back.
//!
//! Per-level scenes ([`LodScenes`]): level scene r holds every leaf instance of the input
//! scene, in the same order (so a hit's instance index means the same object at every
//! level). Without the distance criterion the instance has the mesh of level r. With it
//! (§2.2: the distance of the object's bounding box from the viewer gives LOD⁽⁰⁾, its
//! highest model) the two LODs multiply as in §3 (`LOD⁽¹⁾ = LOD⁽⁰⁾·(1 − d)^f`, and so on
//! down the tree): level scene r holds model `level_of(LOD⁽⁰⁾ · (lvl_max − r)/lvl_max)`,
//! the product with the largest ray LOD that maps to level r. Scenes are per ray level, not
//! per ray LOD, so this is the paper's per-ray product rounded towards detail: never a
//! coarser model than the paper's, at most one level finer. (Adding the two *levels*
//! instead would be coarser than the paper: LOD⁽⁰⁾ = 0.5 and a ray LOD of 4/7 gave level 6,
//! 1/7 of the triangles, where the product 2/7 asks for level 5.)

use crate::error::{Error, Result};
use crate::scene::{Instance, Mesh, Scene, Target};
use glam::{Affine3A, Vec3};
use rayon::prelude::*;
use std::collections::HashMap;
use std::time::Instant;

/// Meshes with fewer triangles are not simplified.
pub const MIN_TRIANGLES: usize = 32;
/// Most levels per mesh (the paper used up to 8).
pub const MAX_LEVELS: u32 = 8;

/// The level of model to use for a level of detail: `k = lvl_max − ⌈LOD·lvl_max⌉` (§2),
/// with LOD clamped to [0, 1] (NaN counts as full detail).
#[inline]
pub fn level_of(lod: f32, lvl_max: u32) -> u32 {
    let lod = if lod.is_nan() { 1.0 } else { lod.clamp(0.0, 1.0) };
    // The small tolerance keeps LOD = j/lvl_max (exactly representable or not) at level
    // lvl_max − j instead of rounding up through float error.
    let j = ((lod * lvl_max as f32) - 1e-5).ceil().max(0.0) as u32;
    lvl_max - j.min(lvl_max)
}

/// Fraction of the original triangles that level k keeps.
pub fn level_fraction(k: u32, lvl_max: u32) -> f32 {
    if lvl_max == 0 || k == 0 {
        return 1.0;
    }
    ((lvl_max - k.min(lvl_max)) as f32 / lvl_max as f32).max(0.5 / lvl_max as f32)
}

/// One mesh at every level (`levels[0]` is the original).
#[derive(Clone, Debug)]
pub struct LodChain {
    pub levels: Vec<Mesh>,
    /// Relative geometric error meshoptimizer reports per level (0 for the original).
    pub errors: Vec<f32>,
}

impl LodChain {
    /// Builds `n_levels` (1..=8) levels of `mesh`.
    pub fn build(mesh: &Mesh, n_levels: u32) -> LodChain {
        let lvl_max = n_levels.saturating_sub(1);
        let mut levels = vec![mesh.clone()];
        let mut errors = vec![0.0];
        let n = mesh.tris.len();
        for k in 1..=lvl_max {
            if n < MIN_TRIANGLES {
                levels.push(mesh.clone());
                errors.push(0.0);
                continue;
            }
            let target = ((n as f32 * level_fraction(k, lvl_max)).ceil() as usize).max(1);
            let (m, e) = simplify(mesh, target);
            // Never more triangles than the previous level, never empty.
            if m.tris.is_empty() || m.tris.len() > levels[k as usize - 1].tris.len() {
                let prev = levels[k as usize - 1].clone();
                errors.push(errors[k as usize - 1]);
                levels.push(prev);
            } else {
                levels.push(m);
                errors.push(e);
            }
        }
        LodChain { levels, errors }
    }
}

/// The on-disk chain cache (shared with the point hierarchies of `multires`).
pub use crate::core::cache::cache_dir;

/// Cache key of a mesh's chain: a hash of the geometry, the materials, the level count and
/// the code version and the text of this file (so a changed simplifier never reads old
/// files).
fn chain_key(mesh: &Mesh, n_levels: u32) -> u64 {
    use std::hash::{Hash, Hasher};
    let mut h = std::collections::hash_map::DefaultHasher::new();
    ("lodchain-v1", env!("CARGO_PKG_VERSION"), n_levels, mesh.tris.len(), mesh.vertex_count()).hash(&mut h);
    // The chain builder's own source, as the point-tree cache does: a changed builder never
    // reads a chain an older one wrote, bumped version or not.
    include_str!("chain.rs").hash(&mut h);
    for v in [&mesh.px, &mesh.py, &mesh.pz, &mesh.nx, &mesh.ny, &mesh.nz] {
        for x in v.iter() {
            x.to_bits().hash(&mut h);
        }
    }
    mesh.tris.hash(&mut h);
    mesh.mat.hash(&mut h);
    h.finish()
}

impl LodChain {
    /// [`LodChain::build`] through the on-disk cache: built once, then read back (levels ≥ 1
    /// as vertex and index arrays; level 0 is the input mesh itself).
    pub fn cached(mesh: &Mesh, n_levels: u32) -> LodChain {
        let Some(dir) = cache_dir() else { return LodChain::build(mesh, n_levels) };
        let path = dir.join(format!("{:016x}.lod", chain_key(mesh, n_levels)));
        if let Some(c) = crate::core::cache::read_cache_file(&path).and_then(|b| decode_chain(&b, mesh, n_levels)) {
            return c;
        }
        let c = LodChain::build(mesh, n_levels);
        // Best effort: a failed write only means a rebuild next time.
        let _ = crate::core::cache::write_atomic(&path, &encode_chain(&c));
        c
    }
}

fn encode_chain(c: &LodChain) -> Vec<u8> {
    let mut b = Vec::new();
    let put = |b: &mut Vec<u8>, x: u32| b.extend_from_slice(&x.to_le_bytes());
    put(&mut b, c.levels.len() as u32);
    for (m, e) in c.levels.iter().zip(&c.errors).skip(1) {
        put(&mut b, e.to_bits());
        put(&mut b, m.vertex_count() as u32);
        put(&mut b, m.tris.len() as u32);
        put(&mut b, m.has_normals() as u32);
        for v in [&m.px, &m.py, &m.pz] {
            v.iter().for_each(|x| put(&mut b, x.to_bits()));
        }
        if m.has_normals() {
            for v in [&m.nx, &m.ny, &m.nz] {
                v.iter().for_each(|x| put(&mut b, x.to_bits()));
            }
        }
        m.tris.iter().flatten().for_each(|&i| put(&mut b, i));
        m.mat.iter().for_each(|&i| put(&mut b, i));
    }
    b
}

/// Reads a cached chain; None on any inconsistency (then it is rebuilt).
fn decode_chain(b: &[u8], mesh: &Mesh, n_levels: u32) -> Option<LodChain> {
    let mut at = 0usize;
    let mut get = || -> Option<u32> {
        let x = u32::from_le_bytes(b.get(at..at + 4)?.try_into().ok()?);
        at += 4;
        Some(x)
    };
    let n = get()?;
    if n != n_levels.max(1) {
        return None;
    }
    let mut levels = vec![mesh.clone()];
    let mut errors = vec![0.0];
    for _ in 1..n {
        errors.push(f32::from_bits(get()?));
        let (nv, nt, has_n) = (get()? as usize, get()? as usize, get()? != 0);
        if nv > 1 << 28 || nt > 1 << 28 {
            return None;
        }
        let mut m = Mesh::new(mesh.name.clone());
        let mut floats = |k: usize| -> Option<Vec<f32>> { (0..k).map(|_| get().map(f32::from_bits)).collect() };
        m.px = floats(nv)?;
        m.py = floats(nv)?;
        m.pz = floats(nv)?;
        if has_n {
            m.nx = floats(nv)?;
            m.ny = floats(nv)?;
            m.nz = floats(nv)?;
        }
        let mut tris = Vec::with_capacity(nt);
        for _ in 0..nt {
            let t = [get()?, get()?, get()?];
            if t.iter().any(|&i| i as usize >= nv) {
                return None;
            }
            tris.push(t);
        }
        m.tris = tris;
        m.mat = (0..nt).map(|_| get()).collect::<Option<_>>()?;
        if m.tris.is_empty() {
            return None;
        }
        // Values a simplification of `mesh` can hold (stop 57: a forged or damaged file's NaN
        // vertex or foreign material was trusted): finite numbers, the mesh's own materials.
        let fin = |v: &[f32]| v.iter().all(|x| x.is_finite());
        let max_mat = mesh.mat.iter().copied().max().unwrap_or(0);
        let e = *errors.last()?;
        if !([&m.px, &m.py, &m.pz, &m.nx, &m.ny, &m.nz].iter().all(|v| fin(v)) && e.is_finite() && e >= 0.0)
            || m.mat.iter().any(|&x| x > max_mat)
        {
            return None;
        }
        levels.push(m);
    }
    (at == b.len()).then_some(LodChain { levels, errors })
}

/// Simplifies to about `target` triangles; returns the mesh and meshoptimizer's relative error.
fn simplify(mesh: &Mesh, target: usize) -> (Mesh, f32) {
    let pos: Vec<[f32; 3]> = (0..mesh.vertex_count()).map(|i| [mesh.px[i], mesh.py[i], mesh.pz[i]]).collect();
    // Triangles grouped by material, in first-seen order.
    let mut groups: Vec<(u32, Vec<u32>)> = Vec::new();
    let mut gi: HashMap<u32, usize> = HashMap::new();
    for (t, tri) in mesh.tris.iter().enumerate() {
        let g = *gi.entry(mesh.mat[t]).or_insert_with(|| {
            groups.push((mesh.mat[t], Vec::new()));
            groups.len() - 1
        });
        groups[g].1.extend_from_slice(tri);
    }
    let n = mesh.tris.len() as f64;
    let opts = if groups.len() > 1 { meshopt::SimplifyOptions::LockBorder } else { meshopt::SimplifyOptions::None };
    let mut out = Mesh::new(mesh.name.clone());
    let mut remap = vec![u32::MAX; mesh.vertex_count()];
    let mut err_max = 0.0f32;
    for (mat, idx) in &groups {
        let g_target = ((target as f64 * (idx.len() / 3) as f64 / n).ceil() as usize).max(1) * 3;
        let mut err = 0.0f32;
        let r = meshopt::simplify_decoder(idx, &pos, g_target, 1.0, opts, Some(&mut err));
        err_max = err_max.max(err);
        for t in r.chunks_exact(3) {
            let mut tri = [0u32; 3];
            for (c, &v) in t.iter().enumerate() {
                if remap[v as usize] == u32::MAX {
                    remap[v as usize] = out.px.len() as u32;
                    let i = v as usize;
                    out.px.push(mesh.px[i]);
                    out.py.push(mesh.py[i]);
                    out.pz.push(mesh.pz[i]);
                    if mesh.has_normals() {
                        out.nx.push(mesh.nx[i]);
                        out.ny.push(mesh.ny[i]);
                        out.nz.push(mesh.nz[i]);
                    }
                }
                tri[c] = remap[v as usize];
            }
            out.tris.push(tri);
            out.mat.push(*mat);
        }
    }
    (out, err_max)
}

/// Parameters of the chains and of the distance criterion.
#[derive(Clone, Debug)]
pub struct ChainParams {
    /// Levels per mesh including the original (1..=8; paper: up to 8).
    pub levels: u32,
    /// Distance criterion: objects farther than this from the eye get LOD = dist₀/distance
    /// as their highest model (None = off, as in the paper's measurements).
    pub distance: Option<f32>,
}

/// The input scene at every level: `scenes[r]` is what a ray of level r intersects.
pub struct LodScenes {
    pub scenes: Vec<Scene>,
    pub chains: Vec<LodChain>,
    /// Level of each leaf instance's highest model, from the distance criterion (0 without it).
    pub offsets: Vec<u32>,
    pub lvl_max: u32,
    pub build_seconds: f64,
}

impl ChainParams {
    /// The ranges of `--lod-levels` and `--lod-distance` (checked again by
    /// [`LodScenes::build`]; `LodArgs::params` checks them before any work).
    pub fn validate(&self) -> Result<()> {
        if self.levels == 0 || self.levels > MAX_LEVELS {
            return Err(Error::Usage(format!("--lod-levels {} out of range (1..={MAX_LEVELS})", self.levels)));
        }
        if let Some(d) = self.distance {
            if !(d.is_finite() && d > 0.0) {
                return Err(Error::Usage(format!("--lod-distance {d} must be a positive distance")));
            }
        }
        Ok(())
    }
}

impl LodScenes {
    pub fn build(scene: &Scene, p: &ChainParams) -> Result<LodScenes> {
        p.validate()?;
        let t0 = Instant::now();
        let lvl_max = p.levels - 1;
        let leaves = scene.leaf_instances()?;
        let chains: Vec<LodChain> = scene.meshes.par_iter().map(|m| LodChain::cached(m, p.levels)).collect();
        let eye = scene.camera.eye;
        // LOD⁽⁰⁾ of each leaf instance (1 without the distance criterion).
        let lod0: Vec<f32> = leaves
            .iter()
            .map(|l| match p.distance {
                None => 1.0,
                Some(d0) => {
                    let (lo, hi) = scene.meshes[l.mesh as usize].bounds();
                    let dist = world_box_distance(&l.xform, lo, hi, eye);
                    if dist <= d0 {
                        1.0
                    } else {
                        d0 / dist
                    }
                }
            })
            .collect();
        let offsets: Vec<u32> = lod0.iter().map(|&x| level_of(x, lvl_max)).collect();
        let mut scenes = Vec::with_capacity(p.levels as usize);
        for r in 0..=lvl_max {
            let mut s = scene.clone_without_geometry();
            let mut ids: HashMap<(u32, u32), u32> = HashMap::new();
            // The largest ray LOD that maps to level r.
            let ray_lod = if lvl_max == 0 { 1.0 } else { (lvl_max - r) as f32 / lvl_max as f32 };
            for (o, l) in leaves.iter().enumerate() {
                let k = level_of(lod0[o] * ray_lod, lvl_max);
                let id = *ids.entry((l.mesh, k)).or_insert_with(|| {
                    s.meshes.push(chains[l.mesh as usize].levels[k as usize].clone());
                    (s.meshes.len() - 1) as u32
                });
                s.groups[0].children.push(Instance { target: Target::Mesh(id), xform: l.xform, material: l.material });
            }
            scenes.push(s);
        }
        Ok(LodScenes { scenes, chains, offsets, lvl_max, build_seconds: t0.elapsed().as_secs_f64() })
    }

    /// Instanced triangles of each level scene.
    pub fn triangles_per_level(&self) -> Vec<u64> {
        self.scenes.iter().map(|s| s.triangle_counts().map(|c| c.0).unwrap_or(0)).collect()
    }
}

/// Distance from `eye` to the world-space bounding box of a transformed object box.
fn world_box_distance(x: &Affine3A, lo: Vec3, hi: Vec3, eye: Vec3) -> f32 {
    let mut wlo = Vec3::splat(f32::INFINITY);
    let mut whi = Vec3::splat(f32::NEG_INFINITY);
    for i in 0..8 {
        let c = Vec3::new(if i & 1 == 0 { lo.x } else { hi.x }, if i & 2 == 0 { lo.y } else { hi.y }, if i & 4 == 0 { lo.z } else { hi.z });
        let w = x.transform_point3(c);
        wlo = wlo.min(w);
        whi = whi.max(w);
    }
    (eye.clamp(wlo, whi) - eye).length()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::builtin::uv_sphere;

    #[test]
    fn level_mapping_matches_the_formula_at_both_ends() {
        for lvl_max in [1u32, 3, 7] {
            assert_eq!(level_of(1.0, lvl_max), 0);
            assert_eq!(level_of(0.0, lvl_max), lvl_max);
            // Just above zero: the coarsest model that still has triangles for LOD > 0.
            assert_eq!(level_of(1e-3, lvl_max), lvl_max - 1);
            for j in 0..=lvl_max {
                let lod = j as f32 / lvl_max as f32;
                assert_eq!(level_of(lod, lvl_max), lvl_max - j, "lod {lod} lvl_max {lvl_max}");
                // Every level keeps at least the fraction LOD of the triangles.
                assert!(level_fraction(level_of(lod, lvl_max), lvl_max) >= lod - 1e-6);
            }
        }
        assert_eq!(level_of(f32::NAN, 7), 0);
        assert_eq!(level_of(2.0, 7), 0);
        assert_eq!(level_of(-1.0, 7), 7);
        assert_eq!(level_of(0.5, 8), 4);
    }

    #[test]
    fn chain_is_monotone_and_keeps_at_least_the_fraction() {
        let m = uv_sphere(48, 96, 0);
        let n = m.tris.len();
        let c = LodChain::build(&m, 8);
        assert_eq!(c.levels.len(), 8);
        assert_eq!(c.levels[0].tris.len(), n);
        for k in 1..8 {
            let t = c.levels[k].tris.len();
            assert!(t <= c.levels[k - 1].tris.len());
            assert!(t > 0);
            assert!(t as f32 >= 0.9 * level_fraction(k as u32, 7) * n as f32, "level {k}: {t} of {n}");
            // Indices in range, normals carried.
            let nv = c.levels[k].vertex_count() as u32;
            assert!(c.levels[k].tris.iter().all(|tr| tr.iter().all(|&i| i < nv)));
            assert_eq!(c.levels[k].nx.len(), c.levels[k].px.len());
        }
        assert!(c.levels[7].tris.len() < n / 4);
    }

    #[test]
    fn cache_round_trips_and_rejects_garbage() {
        let m = uv_sphere(20, 40, 0);
        let c = LodChain::build(&m, 5);
        let b = encode_chain(&c);
        let d = decode_chain(&b, &m, 5).expect("decodes");
        for (a, b) in c.levels.iter().zip(&d.levels) {
            assert_eq!(a.tris, b.tris);
            assert_eq!(a.px, b.px);
            assert_eq!(a.nz, b.nz);
            assert_eq!(a.mat, b.mat);
        }
        assert!(decode_chain(&b, &m, 6).is_none());
        assert!(decode_chain(&b[..b.len() - 3], &m, 5).is_none());
        let mut bad = b.clone();
        let n = bad.len();
        bad[n - 8..n - 4].copy_from_slice(&u32::MAX.to_le_bytes());
        let _ = decode_chain(&bad, &m, 5); // never panics
                                           // A NaN vertex or a material the mesh does not have (stop 57).
        let mut nan = c.clone();
        nan.levels[2].py[0] = f32::NAN;
        assert!(decode_chain(&encode_chain(&nan), &m, 5).is_none(), "NaN vertex");
        let mut foreign = c.clone();
        foreign.levels[1].mat[0] = 7;
        assert!(decode_chain(&encode_chain(&foreign), &m, 5).is_none(), "foreign material");
        assert_ne!(chain_key(&m, 5), chain_key(&m, 6));
    }

    #[test]
    fn tiny_meshes_keep_the_original() {
        let m = crate::scene::builtin::cube_mesh(0);
        let c = LodChain::build(&m, 8);
        assert!(c.levels.iter().all(|l| l.tris.len() == m.tris.len()));
    }
}
