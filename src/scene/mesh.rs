//! Triangle meshes stored as struct-of-arrays (positions, normals, indices, per-triangle
//! material). Unique meshes are shared by every instance that refers to them.

use glam::Vec3;

/// A triangle mesh. Positions and normals are split per component (SoA); `normals` may be
/// empty until [`Mesh::compute_normals`] fills them with area-weighted vertex normals.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    pub name: String,
    pub px: Vec<f32>,
    pub py: Vec<f32>,
    pub pz: Vec<f32>,
    pub nx: Vec<f32>,
    pub ny: Vec<f32>,
    pub nz: Vec<f32>,
    /// Vertex indices of each triangle.
    pub tris: Vec<[u32; 3]>,
    /// Scene material index of each triangle.
    pub mat: Vec<u32>,
}

impl Mesh {
    pub fn new(name: impl Into<String>) -> Self {
        Mesh { name: name.into(), ..Default::default() }
    }
    #[inline(always)]
    pub fn pos(&self, i: u32) -> Vec3 {
        let i = i as usize;
        Vec3::new(self.px[i], self.py[i], self.pz[i])
    }
    #[inline(always)]
    pub fn normal(&self, i: u32) -> Vec3 {
        let i = i as usize;
        Vec3::new(self.nx[i], self.ny[i], self.nz[i])
    }
    pub fn vertex_count(&self) -> usize {
        self.px.len()
    }
    pub fn tri_count(&self) -> usize {
        self.tris.len()
    }
    pub fn push_vertex(&mut self, p: Vec3) -> u32 {
        self.px.push(p.x);
        self.py.push(p.y);
        self.pz.push(p.z);
        (self.px.len() - 1) as u32
    }
    pub fn push_tri(&mut self, a: u32, b: u32, c: u32, mat: u32) {
        self.tris.push([a, b, c]);
        self.mat.push(mat);
    }
    #[inline(always)]
    pub fn tri_verts(&self, t: usize) -> [Vec3; 3] {
        let [a, b, c] = self.tris[t];
        [self.pos(a), self.pos(b), self.pos(c)]
    }
    pub fn has_normals(&self) -> bool {
        !self.nx.is_empty() && self.nx.len() == self.px.len()
    }
    /// Area-weighted vertex normals (for meshes without normals, e.g. OFF files).
    /// (v1 − v0) × (v2 − v0) of triangle t in f64: twice its area and its normal. In f32, a
    /// mesh ~1e10 wide overflows the squared length (zero normals, infinite areas).
    pub fn tri_cross(&self, t: usize) -> glam::DVec3 {
        let [p0, p1, p2] = self.tri_verts(t).map(Vec3::as_dvec3);
        (p1 - p0).cross(p2 - p0)
    }
    pub fn compute_normals(&mut self) {
        // Summed in f64 (see `tri_cross`).
        let n = self.vertex_count();
        let mut acc = vec![glam::DVec3::ZERO; n];
        for t in 0..self.tris.len() {
            let [a, b, c] = self.tris[t];
            let fnrm = self.tri_cross(t);
            if fnrm.is_finite() {
                for i in [a, b, c] {
                    acc[i as usize] += fnrm;
                }
            }
        }
        let unit: Vec<Vec3> = acc.iter().map(|v| v.normalize_or_zero().as_vec3()).collect();
        self.nx = unit.iter().map(|v| v.x).collect();
        self.ny = unit.iter().map(|v| v.y).collect();
        self.nz = unit.iter().map(|v| v.z).collect();
    }
    /// Whether the mesh is closed: with vertices welded by exact position, every edge is
    /// shared by exactly two triangles (the surface of a solid; a sphere, a cube, a closed
    /// scan), so a line through it crosses it as often inwards as outwards.
    pub fn is_closed(&self) -> bool {
        if self.tris.is_empty() {
            return false;
        }
        let mut id = std::collections::HashMap::new();
        let weld: Vec<u32> = (0..self.vertex_count() as u32)
            .map(|i| {
                let p = self.pos(i);
                let n = id.len() as u32;
                *id.entry([p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]).or_insert(n)
            })
            .collect();
        let mut edges = std::collections::HashMap::new();
        for t in &self.tris {
            for k in 0..3 {
                let (a, b) = (weld[t[k] as usize], weld[t[(k + 1) % 3] as usize]);
                if a == b {
                    return false;
                }
                *edges.entry((a.min(b), a.max(b))).or_insert(0u32) += 1;
            }
        }
        edges.values().all(|&n| n == 2)
    }
    /// Removes triangles with non-finite vertices or zero area; returns how many were removed.
    pub fn remove_degenerate(&mut self) -> usize {
        let before = self.tris.len();
        let mut keep_t = Vec::with_capacity(before);
        let mut keep_m = Vec::with_capacity(before);
        for t in 0..before {
            let [p0, p1, p2] = self.tri_verts(t);
            let ok = p0.is_finite() && p1.is_finite() && p2.is_finite() && (p1 - p0).cross(p2 - p0).length_squared() > 0.0;
            if ok {
                keep_t.push(self.tris[t]);
                keep_m.push(self.mat[t]);
            }
        }
        self.tris = keep_t;
        self.mat = keep_m;
        before - self.tris.len()
    }
    /// Removes triangles that repeat an earlier one exactly: the same three vertex positions
    /// in the same winding (any rotation of the three) and the same material; returns how
    /// many were removed. A copy adds nothing to an image (its hits tie with the original's),
    /// but coincident primitives make obvhs' PLOC build quadratic (stop 46's sweep: 20,000
    /// copies of one triangle took 35 s). The opposite winding is kept (a back face).
    pub fn remove_duplicates(&mut self) -> usize {
        let before = self.tris.len();
        let mut seen = std::collections::HashSet::with_capacity(before);
        let mut keep_t = Vec::with_capacity(before);
        let mut keep_m = Vec::with_capacity(before);
        for t in 0..before {
            let v = self.tri_verts(t).map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()]);
            // The rotation that starts at the smallest vertex: one key per winding.
            let r = (0..3).min_by_key(|&i| v[i]).unwrap_or(0);
            let key = ([v[r], v[(r + 1) % 3], v[(r + 2) % 3]], self.mat[t]);
            if seen.insert(key) {
                keep_t.push(self.tris[t]);
                keep_m.push(self.mat[t]);
            }
        }
        self.tris = keep_t;
        self.mat = keep_m;
        before - self.tris.len()
    }
    /// Axis-aligned bounds over the vertices that triangles use (min, max).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for t in &self.tris {
            for &i in t {
                let p = self.pos(i);
                lo = lo.min(p);
                hi = hi.max(p);
            }
        }
        (lo, hi)
    }
    /// Appends `other` (with its own materials) transformed by `xf`.
    pub fn append(&mut self, other: &Mesh, xf: &glam::Affine3A) {
        let base = self.vertex_count() as u32;
        let with_n = self.has_normals() || self.vertex_count() == 0;
        for i in 0..other.vertex_count() as u32 {
            self.push_vertex(xf.transform_point3(other.pos(i)));
        }
        if with_n && other.has_normals() {
            let nm = glam::Mat3::from(xf.matrix3).inverse().transpose();
            for i in 0..other.vertex_count() as u32 {
                let n = (nm * other.normal(i)).normalize_or_zero();
                self.nx.push(n.x);
                self.ny.push(n.y);
                self.nz.push(n.z);
            }
        } else {
            self.nx.clear();
            self.ny.clear();
            self.nz.clear();
        }
        for (t, m) in other.tris.iter().zip(other.mat.iter()) {
            self.push_tri(t[0] + base, t[1] + base, t[2] + base, *m);
        }
    }
    /// Bytes held by this mesh's arrays.
    pub fn memory_bytes(&self) -> usize {
        4 * (self.px.len() * 3 + self.nx.len() * 3 + self.tris.len() * 4)
    }
}
