//! Surfel models (Adams et al. §3): surfels with position, normal, tangent axes and radius,
//! grouped in *surfel collections* between which clipping relations are stored (§4.3).
//!
//! - Positions, normals and radii are struct-of-arrays. The tangent axes are not stored: the
//!   undeformed axes of surfel i are `onb(n_i)` scaled by `r_i` (a pure function, so build
//!   and render agree); the deformed axes follow from Eq. 1's gradient term (see `displace`).
//! - From meshes: either one surfel per vertex (normal = area-weighted vertex normal, radius =
//!   the longest incident edge, so the discs cover every incident triangle), or a target
//!   number of area samples (stratified candidates thinned on a voxel grid, seeded hash:
//!   deterministic), radius 1.2× the distance to the 4th nearest sample.
//! - Analytic generators (sphere, planar disc) for the built-in sequences and the
//!   known-answer tests.

use super::DeformError;
use crate::core::onb;
use crate::core::rng::{pcg_hash, Sampler};
use crate::scene::Mesh;
use glam::Vec3;

/// Surfels, struct-of-arrays.
#[derive(Clone, Debug, Default)]
pub struct SurfelSoa {
    pub px: Vec<f32>,
    pub py: Vec<f32>,
    pub pz: Vec<f32>,
    /// Unit normal.
    pub nx: Vec<f32>,
    pub ny: Vec<f32>,
    pub nz: Vec<f32>,
    /// Disc radius (the tangent axes have this length).
    pub r: Vec<f32>,
}

impl SurfelSoa {
    pub fn len(&self) -> usize {
        self.px.len()
    }
    pub fn is_empty(&self) -> bool {
        self.px.is_empty()
    }
    #[inline(always)]
    pub fn pos(&self, i: usize) -> Vec3 {
        Vec3::new(self.px[i], self.py[i], self.pz[i])
    }
    #[inline(always)]
    pub fn normal(&self, i: usize) -> Vec3 {
        Vec3::new(self.nx[i], self.ny[i], self.nz[i])
    }
    /// Undeformed tangent axes (u, v), each of length `r`.
    #[inline(always)]
    pub fn axes(&self, i: usize) -> (Vec3, Vec3) {
        let (t, b) = onb(self.normal(i));
        (t * self.r[i], b * self.r[i])
    }
    pub fn push(&mut self, p: Vec3, n: Vec3, r: f32) {
        self.px.push(p.x);
        self.py.push(p.y);
        self.pz.push(p.z);
        self.nx.push(n.x);
        self.ny.push(n.y);
        self.nz.push(n.z);
        self.r.push(r);
    }
    pub fn positions(&self) -> Vec<Vec3> {
        (0..self.len()).map(|i| self.pos(i)).collect()
    }
    pub fn append(&mut self, o: &SurfelSoa) {
        for i in 0..o.len() {
            self.push(o.pos(i), o.normal(i), o.r[i]);
        }
    }
    /// Checks every surfel: finite position, unit normal (renormalised if merely not unit),
    /// positive finite radius, no two surfels at the same position.
    pub fn validate(&mut self) -> Result<(), DeformError> {
        self.validate_values()?;
        self.check_duplicates(0..self.len())
    }

    /// [`validate`](Self::validate) without the duplicate check.
    pub fn validate_values(&mut self) -> Result<(), DeformError> {
        // A splat wider than the whole model is a unit mix-up (1e20 made the object vanish
        // from every frame, 1e10 garbled it); the bound is the positions' box diagonal.
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for i in 0..self.len() {
            let p = self.pos(i);
            if p.is_finite() {
                (lo, hi) = (lo.min(p), hi.max(p));
            }
        }
        let diag = if lo.x <= hi.x { (hi - lo).length() } else { 0.0 };
        for i in 0..self.len() {
            let p = self.pos(i);
            if !p.is_finite() {
                return Err(DeformError::BadSurfel { index: i, msg: format!("non-finite position {p}") });
            }
            if p.abs().max_element() > crate::scene::MAX_COORD {
                return Err(DeformError::BadSurfel {
                    index: i,
                    msg: format!("position {p} beyond ±{:e}: scale the model down", crate::scene::MAX_COORD),
                });
            }
            // Scaled to its largest component first: (1e30, 1e30, 0) is a fine direction whose
            // length overflows f32.
            let n0 = self.normal(i);
            let big = n0.abs().max_element();
            if !(n0.is_finite() && big > 0.0) {
                return Err(DeformError::BadSurfel { index: i, msg: format!("zero or non-finite normal {n0}") });
            }
            // The largest component is now ±1, so the length lies in [1, √3].
            let n = (n0 / big).normalize();
            self.nx[i] = n.x;
            self.ny[i] = n.y;
            self.nz[i] = n.z;
            if !(self.r[i].is_finite() && self.r[i] > 0.0) {
                return Err(DeformError::BadSurfel { index: i, msg: format!("radius {}", self.r[i]) });
            }
            if diag > 0.0 && self.r[i] > diag {
                return Err(DeformError::BadSurfel {
                    index: i,
                    msg: format!(
                        "radius {:e} is wider than the whole model ({diag:e} across): radii are in the positions' units",
                        self.r[i]
                    ),
                });
            }
        }
        // Every radius a millionth of the model or less: even 10^8 surfels spread over it
        // would leave gaps 100 times their size, and no ray hits (a unit mix-up, as above).
        if let Some((i, &r)) = self.r.iter().enumerate().max_by(|a, b| a.1.total_cmp(b.1)) {
            if diag > 0.0 && r < 1e-6 * diag {
                return Err(DeformError::BadSurfel {
                    index: i,
                    msg: format!(
                        "the largest radius, {r:e}, is below a millionth of the model ({diag:e} across): the surfels would not cover the surface; radii are in the positions' units"
                    ),
                });
            }
        }
        Ok(())
    }

    /// Errors if two surfels in `range` share a position (they would make MLS weights and
    /// the neighbourhoods degenerate). Different surfaces may share points (an edge).
    pub fn check_duplicates(&self, range: std::ops::Range<usize>) -> Result<(), DeformError> {
        let mut keys: Vec<(u32, u32, u32, u32)> = range
            .map(|i| {
                let [x, y, z] = pos_key(self.pos(i));
                (x, y, z, i as u32)
            })
            .collect();
        keys.sort_unstable();
        for w in keys.windows(2) {
            if (w[0].0, w[0].1, w[0].2) == (w[1].0, w[1].1, w[1].2) {
                return Err(DeformError::DuplicatePoint { a: w[0].3 as usize, b: w[1].3 as usize });
            }
        }
        Ok(())
    }
}

/// A position as a hashable key, equal exactly where the positions are equal as f32 numbers:
/// −0.0 counts as +0.0 (their bits differ; adding +0.0 turns −0.0 into +0.0 and changes
/// nothing else). The duplicate checks and the mesh vertices' de-duplication use it.
#[inline]
fn pos_key(p: Vec3) -> [u32; 3] {
    [(p.x + 0.0).to_bits(), (p.y + 0.0).to_bits(), (p.z + 0.0).to_bits()]
}

/// A named range of surfels forming one surface (§4.3 "surfel collections").
#[derive(Clone, Debug, PartialEq)]
pub struct Collection {
    pub name: String,
    /// Surfels `start..end` of the model.
    pub start: u32,
    pub end: u32,
    /// Display colour hint for renderers (linear RGB).
    pub color: [f32; 3],
}

/// Surfels of one deformable object, their collections, and clipping relations: a pair
/// `(a, b)` clips collection `a` against `b` *and* `b` against `a` (§4.3); a point of one
/// surface is rejected where it lies outside the other (normals point out of the solid).
#[derive(Clone, Debug, Default)]
pub struct SurfelModel {
    pub surfels: SurfelSoa,
    pub collections: Vec<Collection>,
    pub clip: Vec<(u32, u32)>,
}

impl SurfelModel {
    /// A model of one collection.
    pub fn single(name: &str, surfels: SurfelSoa, color: [f32; 3]) -> Self {
        let n = surfels.len() as u32;
        SurfelModel { surfels, collections: vec![Collection { name: name.into(), start: 0, end: n, color }], clip: Vec::new() }
    }
    /// Appends a collection; returns its index.
    pub fn add_collection(&mut self, name: &str, s: &SurfelSoa, color: [f32; 3]) -> u32 {
        let start = self.surfels.len() as u32;
        self.surfels.append(s);
        self.collections.push(Collection { name: name.into(), start, end: self.surfels.len() as u32, color });
        (self.collections.len() - 1) as u32
    }
    pub fn len(&self) -> usize {
        self.surfels.len()
    }
    pub fn is_empty(&self) -> bool {
        self.surfels.is_empty()
    }
    /// Collection index of every surfel.
    pub fn collection_of(&self) -> Vec<u32> {
        let mut c = vec![0u32; self.len()];
        for (k, col) in self.collections.iter().enumerate() {
            c[col.start as usize..col.end as usize].fill(k as u32);
        }
        c
    }
    /// Surfel validation plus structural checks (collections tile the surfels, clip pairs valid).
    pub fn validate(&mut self) -> Result<(), DeformError> {
        if self.surfels.len() < 4 {
            return Err(DeformError::TooSmall(format!("{} surfels (need at least 4)", self.surfels.len())));
        }
        self.surfels.validate_values()?;
        let mut next = 0u32;
        for c in &self.collections {
            if c.start != next || c.end <= c.start {
                return Err(DeformError::Invalid(format!("collection '{}' does not tile the surfels", c.name)));
            }
            next = c.end;
        }
        if next as usize != self.surfels.len() {
            return Err(DeformError::Invalid("collections do not cover all surfels".into()));
        }
        for c in &self.collections {
            self.surfels.check_duplicates(c.start as usize..c.end as usize)?;
        }
        for &(a, b) in &self.clip {
            if a == b || a as usize >= self.collections.len() || b as usize >= self.collections.len() {
                return Err(DeformError::Invalid(format!("bad clipping relation ({a}, {b})")));
            }
        }
        Ok(())
    }
}

fn mesh_check(mesh: &Mesh) -> Result<f64, DeformError> {
    // The renderers' bound (`scene::MAX_COORD`): beyond it areas and sampling cells overflow.
    let ext = (0..mesh.vertex_count() as u32).map(|i| mesh.pos(i).abs().max_element()).filter(|e| e.is_finite()).fold(0.0f32, f32::max);
    if ext > crate::scene::MAX_COORD {
        return Err(DeformError::Invalid(format!(
            "mesh '{}' reaches coordinate {ext:.3e}, beyond ±{:e}: scale the model down",
            mesh.name,
            crate::scene::MAX_COORD
        )));
    }
    if mesh.vertex_count() < 4 || mesh.tri_count() == 0 {
        return Err(DeformError::TooSmall(format!(
            "mesh '{}' has {} vertices and {} triangles",
            mesh.name,
            mesh.vertex_count(),
            mesh.tri_count()
        )));
    }
    let mut area = 0.0f64;
    for t in 0..mesh.tri_count() {
        let ar = 0.5 * mesh.tri_cross(t).length();
        if ar.is_finite() {
            area += ar;
        }
    }
    if !(area > 0.0) {
        return Err(DeformError::TooSmall(format!("mesh '{}' has zero surface area", mesh.name)));
    }
    Ok(area)
}

/// One surfel per used mesh vertex; radius = longest incident edge.
pub fn surfels_from_mesh_vertices(mesh: &Mesh) -> Result<SurfelSoa, DeformError> {
    mesh_check(mesh)?;
    let mut m = mesh.clone();
    m.remove_degenerate();
    if !m.has_normals() {
        m.compute_normals();
    }
    let nv = m.vertex_count();
    let mut rad = vec![0.0f32; nv];
    for t in &m.tris {
        for k in 0..3 {
            let (a, b) = (t[k], t[(k + 1) % 3]);
            let l = (m.pos(a) - m.pos(b)).length();
            rad[a as usize] = rad[a as usize].max(l);
            rad[b as usize] = rad[b as usize].max(l);
        }
    }
    // Exact duplicates (split vertices in some files) would make MLS weights degenerate:
    // keep the first vertex at each position.
    let mut seen = std::collections::HashSet::new();
    let mut s = SurfelSoa::default();
    for i in 0..nv {
        let p = m.pos(i as u32);
        let n = m.normal(i as u32);
        if rad[i] > 0.0 && p.is_finite() && n.length_squared() > 0.5 && seen.insert(pos_key(p)) {
            s.push(p, n.normalize(), rad[i]);
        }
    }
    if s.len() < 4 {
        return Err(DeformError::TooSmall(format!("mesh '{}' gives {} usable surfels", mesh.name, s.len())));
    }
    Ok(s)
}

/// About `n` area-uniform samples, deterministic for `seed`: 4n stratified candidates
/// (per triangle ⌊n_t⌋ plus one with probability frac(n_t)) thinned to one per cell of a
/// voxel grid sized for ~n cells (the candidate nearest the cell centre), which spreads them
/// far more evenly than plain random samples. Radius: 1.2× the distance to the 4th nearest
/// sample, so the discs cover the surface. Normals interpolate the vertex normals.
pub fn sample_mesh(mesh: &Mesh, n: usize, seed: u32) -> Result<SurfelSoa, DeformError> {
    let area = mesh_check(mesh)?;
    if n < 4 {
        return Err(DeformError::TooSmall(format!("{n} samples requested")));
    }
    let mut m = mesh.clone();
    m.remove_degenerate();
    if !m.has_normals() {
        m.compute_normals();
    }
    let cand_n = 4 * n;
    let mut cand: Vec<(Vec3, Vec3)> = Vec::with_capacity(cand_n + 16);
    for t in 0..m.tri_count() {
        let [a, b, c] = m.tri_verts(t);
        // Area and geometric normal in f64 (`Mesh::tri_cross`).
        let cr = m.tri_cross(t);
        let (ar, fn_) = (0.5 * cr.length(), cr.normalize_or_zero().as_vec3());
        // In [0, cand_n] (f64 areas cannot overflow for finite f32 vertices).
        let expect = if ar.is_finite() { (ar / area * cand_n as f64).min(cand_n as f64) } else { 0.0 };
        let mut smp = Sampler::new(seed, pcg_hash(t as u32), 0);
        let k = expect.floor() as usize + usize::from((smp.next() as f64) < expect.fract());
        let [ia, ib, ic] = m.tris[t];
        for _ in 0..k {
            let (mut u, mut v) = smp.next2();
            if u + v > 1.0 {
                u = 1.0 - u;
                v = 1.0 - v;
            }
            let p = a + (b - a) * u + (c - a) * v;
            let nn = m.normal(ia) * (1.0 - u - v) + m.normal(ib) * u + m.normal(ic) * v;
            let nn = if nn.length_squared() > 1e-12 { nn.normalize() } else { fn_ };
            if p.is_finite() && nn.is_finite() && nn != Vec3::ZERO {
                cand.push((p, nn));
            }
        }
    }
    let s = thin_to_surfels(&cand, n, area as f32);
    if s.len() < 4 {
        return Err(DeformError::TooSmall(format!("mesh '{}' gives {} samples", mesh.name, s.len())));
    }
    Ok(s)
}

/// Surfels from candidate samples (position, unit normal) spread over a surface of the given
/// area: one candidate per cell of a voxel grid sized for about `n` occupied cells (the one
/// nearest the cell centre; ties to the lower index), radius 1.2× the distance to the 4th
/// nearest kept sample so the discs cover the surface. Shared by [`sample_mesh`] and the
/// implicit character of `sequences` (`character::Goblin::surfels`).
pub(crate) fn thin_to_surfels(cand: &[(Vec3, Vec3)], n: usize, area: f32) -> SurfelSoa {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for (p, _) in cand {
        lo = lo.min(*p);
        hi = hi.max(*p);
    }
    // Cell size adjusted until ~n cells are occupied.
    let mut cell = (area / n.max(1) as f32).sqrt();
    let mut chosen: Vec<(Vec3, Vec3)> = Vec::new();
    for _ in 0..8 {
        let mut best: std::collections::HashMap<(i32, i32, i32), (f32, u32)> = Default::default();
        for (i, (p, _)) in cand.iter().enumerate() {
            let g = (*p - lo) / cell;
            let k = g.floor();
            let d = (g - k - Vec3::splat(0.5)).length_squared();
            let key = (k.x as i32, k.y as i32, k.z as i32);
            let e = best.entry(key).or_insert((f32::INFINITY, u32::MAX));
            if d < e.0 || (d == e.0 && (i as u32) < e.1) {
                *e = (d, i as u32);
            }
        }
        let mut idx: Vec<u32> = best.values().map(|v| v.1).filter(|&i| i != u32::MAX).collect();
        idx.sort_unstable();
        chosen = idx.iter().map(|&i| cand[i as usize]).collect();
        let ratio = chosen.len() as f32 / n as f32;
        if (0.9..1.1).contains(&ratio) {
            break;
        }
        cell *= ratio.sqrt();
    }
    let pts: Vec<Vec3> = chosen.iter().map(|c| c.0).collect();
    let kd = super::knn::KdTree::new(&pts);
    let mut out = Vec::new();
    let mut s = SurfelSoa::default();
    for (i, (p, nn)) in chosen.iter().enumerate() {
        kd.knn(*p, 4, Some(i as u32), &mut out);
        let r = out.last().map(|o| o.1.sqrt() * 1.2).unwrap_or(cell);
        if r > 0.0 {
            s.push(*p, *nn, r);
        }
    }
    s
}

/// `n` surfels on a sphere (Fibonacci lattice), outward normals, radius covering the spacing.
pub fn sphere_surfels(center: Vec3, radius: f32, n: usize) -> SurfelSoa {
    let n = n.max(8);
    let mut s = SurfelSoa::default();
    let ga = std::f32::consts::PI * (3.0 - 5f32.sqrt());
    let spacing = (4.0 * std::f32::consts::PI / n as f32).sqrt() * radius;
    for i in 0..n {
        let y = 1.0 - 2.0 * (i as f32 + 0.5) / n as f32;
        let rr = (1.0 - y * y).max(0.0).sqrt();
        let th = ga * i as f32;
        let d = Vec3::new(rr * th.cos(), y, rr * th.sin());
        s.push(center + d * radius, d, spacing);
    }
    s
}

/// A planar disc of radius `extent` around `center` with normal `n`, sampled on a square
/// grid of the given spacing (radius 0.8·spacing, so the discs overlap).
pub fn disc_surfels(center: Vec3, n: Vec3, extent: f32, spacing: f32) -> SurfelSoa {
    let n = n.normalize();
    let (t, b) = onb(n);
    let k = (extent / spacing).ceil() as i32;
    let mut s = SurfelSoa::default();
    for j in -k..=k {
        for i in -k..=k {
            let (x, y) = (i as f32 * spacing, j as f32 * spacing);
            if x * x + y * y <= extent * extent {
                s.push(center + t * x + b * y, n, 0.8 * spacing);
            }
        }
    }
    s
}

/// A planar rectangle `[u0,u1]×[v0,v1]` in the frame (origin, unit axes `u`, `v`), normal
/// `u × v`, grid-sampled with the given spacing.
pub fn rect_surfels(origin: Vec3, u: Vec3, v: Vec3, (u0, u1): (f32, f32), (v0, v1): (f32, f32), spacing: f32) -> SurfelSoa {
    let n = u.cross(v).normalize();
    let mut s = SurfelSoa::default();
    let nu = ((u1 - u0) / spacing).round().max(1.0) as i32;
    let nv = ((v1 - v0) / spacing).round().max(1.0) as i32;
    for j in 0..=nv {
        for i in 0..=nu {
            let x = u0 + (u1 - u0) * i as f32 / nu as f32;
            let y = v0 + (v1 - v0) * j as f32 / nv as f32;
            s.push(origin + u * x + v * y, n, 0.8 * spacing);
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_surfels_rejected() {
        let mut s = sphere_surfels(Vec3::ZERO, 1.0, 50);
        s.nx[3] = 0.0;
        s.ny[3] = 0.0;
        s.nz[3] = 0.0;
        assert!(matches!(s.clone().validate(), Err(DeformError::BadSurfel { index: 3, .. })));
        let mut s = sphere_surfels(Vec3::ZERO, 1.0, 50);
        s.px[7] = f32::NAN;
        assert!(matches!(s.validate(), Err(DeformError::BadSurfel { index: 7, .. })));
        let mut s = sphere_surfels(Vec3::ZERO, 1.0, 50);
        let p = s.pos(2);
        s.push(p, Vec3::X, 0.1);
        assert!(matches!(s.validate(), Err(DeformError::DuplicatePoint { .. })));
    }

    /// −0.0 and +0.0 are the same coordinate (equal as f32 numbers, as `DuplicatePoint`
    /// says): two surfels at (0, 0, 2) and (−0, 0, 2) are duplicates, and a mesh whose split
    /// vertex differs only in the sign of a zero keeps one surfel there. Until the review of
    /// stop 80 both compared the bits, which differ.
    #[test]
    fn signed_zeros_are_the_same_position() {
        let mut s = sphere_surfels(Vec3::ZERO, 1.0, 50);
        s.push(Vec3::new(0.0, 0.0, 2.0), Vec3::Z, 0.1);
        s.push(Vec3::new(-0.0, 0.0, 2.0), Vec3::Z, 0.1);
        assert!(matches!(s.validate(), Err(DeformError::DuplicatePoint { .. })));
        let mut m = Mesh::new("tet");
        let v = [Vec3::new(0.0, 0.0, 0.0), Vec3::X, Vec3::Y, Vec3::Z, Vec3::new(-0.0, 0.0, 0.0)];
        for p in v {
            m.push_vertex(p);
        }
        for t in [[0, 2, 1], [0, 1, 3], [1, 2, 3], [4, 3, 2]] {
            m.push_tri(t[0], t[1], t[2], 0);
        }
        let s = surfels_from_mesh_vertices(&m).unwrap();
        let at_origin = (0..s.len()).filter(|&i| s.pos(i) == Vec3::ZERO).count();
        assert_eq!(at_origin, 1, "{} surfels at the origin", at_origin);
        s.clone().validate().unwrap();
    }

    #[test]
    fn tiny_mesh_is_an_error() {
        let mut m = Mesh::new("tri");
        let a = m.push_vertex(Vec3::ZERO);
        let b = m.push_vertex(Vec3::X);
        let c = m.push_vertex(Vec3::Y);
        m.push_tri(a, b, c, 0);
        assert!(matches!(surfels_from_mesh_vertices(&m), Err(DeformError::TooSmall(_))));
        assert!(matches!(sample_mesh(&Mesh::new("empty"), 100, 0), Err(DeformError::TooSmall(_))));
    }
}
