//! Flat instances and the shadow cones that leave them (*deviation*: an optimisation the
//! paper does not have; ablation `--no-plane-skip`, bench key `plane=0`).
//!
//! §4.2 starts a shadow cone with the incoming footprint on the tangent plane, and the
//! start distance of `Tracer::shade` clears the surface's own footprint and thickness, so
//! the spawning surface's geometry near the start is rejected point by point and triangle
//! by triangle. For the shadow cones of a checker board, that rejection is most of their
//! work: a cone wide enough to cover several cells descends the board's octree (and its
//! neighbouring patches) around its start, down to the level its footprint selects, only to
//! throw every piece away (stop 29: about half of all shadow-cone tests on `spheres` and
//! `complex`; stop 30 tried a per-node cull below the tangent plane and gained 3 %).
//!
//! A plane cannot shadow a point on itself from a light that lies entirely on one side of
//! it: every segment from the point to the light stays on that side. So when a fragment
//! belongs to a *flat* leaf instance (all vertices of its mesh on one plane) and every point
//! of the light (the centre and the ellipse's axes) lies strictly on the side the fragment
//! faces, the shadow cone skips every instance on that same world plane — the neighbouring
//! board patches too — and every instance-tree slot whose instances all lie on it,
//! instance-level points included. Those points sit up to half a voxel off the plane
//! (`build.rs`, the voxel centres of §3.2), but they stand for the plane, and the start
//! distance rejected them before. The skip changes the image only where the start distance
//! let a piece of the plane through, which is a false self-shadow.

use super::trace::{MLeaf, Tlas, LEAF};
use crate::scene::{Mesh, Scene};
use glam::{Vec3, Vec4};

/// No plane: the instance (or a slot's instances) is not flat, or not all on one plane.
pub const NONE: u32 = u32::MAX;

/// The world planes of the flat leaf instances, and which plane each leaf and each slot of
/// the instance tree lies on.
#[derive(Clone, Debug, Default)]
pub struct FlatPlanes {
    /// (unit normal, offset): a point x lies on plane k when `planes[k].xyz · x + w = 0`.
    pub planes: Vec<Vec4>,
    /// Per leaf instance: its plane, or [`NONE`].
    pub leaf: Vec<u32>,
    /// Per instance-tree slot: the plane all its instances lie on, or [`NONE`].
    pub slot: Vec<u32>,
}

/// Distinct planes kept; instances on further planes count as not flat (correct, only
/// slower). Real scenes have a floor, a few walls.
const MAX_PLANES: usize = 1024;

/// The plane of a flat mesh in object space, (unit normal, offset), or `None` when its
/// vertices are not on one plane (to 1e-5 of its size) or its area is zero.
pub fn mesh_plane(mesh: &Mesh) -> Option<(Vec3, f32)> {
    if mesh.tris.is_empty() {
        return None;
    }
    let mut area_n = Vec3::ZERO;
    for t in &mesh.tris {
        let [a, b, c] = t.map(|i| mesh.pos(i));
        area_n += (b - a).cross(c - a);
    }
    let n = area_n.normalize_or_zero();
    if n == Vec3::ZERO || !n.is_finite() {
        return None;
    }
    let (lo, hi) = mesh.bounds();
    let size = (hi - lo).length();
    if !(size > 0.0 && size.is_finite()) {
        return None;
    }
    let p0 = mesh.pos(mesh.tris[0][0]);
    let d = -n.dot(p0);
    let tol = 1e-5 * size;
    let flat = mesh.tris.iter().flatten().all(|&i| (n.dot(mesh.pos(i)) + d).abs() <= tol);
    flat.then_some((n, d))
}

impl FlatPlanes {
    pub fn build(scene: &Scene, leaves: &[MLeaf], tlas: &Tlas) -> FlatPlanes {
        let mut mesh_planes: Vec<Option<Option<(Vec3, f32)>>> = vec![None; scene.meshes.len()];
        let mut fp = FlatPlanes { planes: Vec::new(), leaf: Vec::with_capacity(leaves.len()), slot: vec![NONE; tlas.child.len()] };
        for l in leaves {
            let mp = *mesh_planes[l.mesh as usize].get_or_insert_with(|| mesh_plane(&scene.meshes[l.mesh as usize]));
            let id = mp.and_then(|(n, d)| {
                // A point of the plane and its normal, to world space.
                let p = l.xform.transform_point3(-d * n);
                let nw = (l.normal_mat * n).normalize_or_zero();
                if nw == Vec3::ZERO || !p.is_finite() {
                    return None;
                }
                // One orientation per plane: the largest component positive.
                let nw = if nw[nw.abs().max_position()] < 0.0 { -nw } else { nw };
                let w = -nw.dot(p);
                let tol = 1e-5 * (1.0 + p.abs().max_element());
                if let Some(k) = fp.planes.iter().position(|q| q.truncate().dot(nw) > 1.0 - 1e-6 && (q.w - w).abs() <= tol) {
                    return Some(k as u32);
                }
                (fp.planes.len() < MAX_PLANES).then(|| {
                    fp.planes.push(nw.extend(w));
                    (fp.planes.len() - 1) as u32
                })
            });
            fp.leaf.push(id.unwrap_or(NONE));
        }
        if !tlas.child.is_empty() {
            fp.fill_slot(tlas, 0);
        }
        fp
    }

    /// Post-order: a slot's plane is its leaf's, or the one plane of all its non-empty
    /// children.
    fn fill_slot(&mut self, tlas: &Tlas, s: usize) -> u32 {
        let ch = tlas.child[s];
        let id = if ch & LEAF != 0 {
            self.leaf[(ch & !LEAF) as usize]
        } else {
            let f = ch as usize;
            let mut id: Option<u32> = None;
            for k in f..f + 8 {
                if tlas.r[k] < 0.0 {
                    continue; // empty slot
                }
                let c = self.fill_slot(tlas, k);
                id = match id {
                    None => Some(c),
                    Some(p) if p == c => Some(p),
                    Some(_) => Some(NONE),
                };
            }
            id.unwrap_or(NONE)
        };
        self.slot[s] = id;
        id
    }

    /// Whether plane `id` cannot shadow a fragment on it with (viewer-facing) normal `n` from
    /// the light at `lp` with ellipse axes `ax_a`, `ax_b` (zero for a point light): the whole
    /// light lies strictly on the side `n` points to.
    pub fn light_clear(&self, id: u32, n: Vec3, lp: Vec3, ax_a: Vec3, ax_b: Vec3) -> bool {
        let Some(q) = self.planes.get(id as usize) else { return false };
        let pn = q.truncate();
        let side = pn.dot(n);
        // The fragment's normal must be the plane's (a merged fragment at a corner is not).
        if side.abs() < 0.5 {
            return false;
        }
        let h = side.signum() * (pn.dot(lp) + q.w) - pn.dot(ax_a).abs() - pn.dot(ax_b).abs();
        h > 1e-4 * (1.0 + lp.abs().max_element())
    }
}

/// The normal matrix of a leaf is kept as a `Mat3`; a helper for tests that build leaves.
#[cfg(test)]
fn normal_mat(x: &glam::Affine3A) -> glam::Mat3 {
    glam::Mat3::from(x.matrix3).inverse().transpose()
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Affine3A;

    fn quad(y: f32) -> Mesh {
        let mut m = Mesh::new("quad");
        for (x, z) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            m.px.push(x);
            m.py.push(y);
            m.pz.push(z);
            m.nx.push(0.0);
            m.ny.push(1.0);
            m.nz.push(0.0);
        }
        m.tris = vec![[0, 2, 1], [0, 3, 2]];
        m.mat = vec![0, 0];
        m
    }

    #[test]
    fn flat_meshes_are_found_and_bent_or_empty_ones_are_not() {
        let q = quad(2.0);
        let (n, d) = mesh_plane(&q).expect("flat");
        assert!((n.y.abs() - 1.0).abs() < 1e-6 && (n.dot(Vec3::new(0.3, 2.0, 0.7)) + d).abs() < 1e-6);
        let mut bent = quad(0.0);
        bent.py[2] = 0.01;
        assert!(mesh_plane(&bent).is_none());
        let mut empty = quad(0.0);
        empty.tris.clear();
        assert!(mesh_plane(&empty).is_none());
        // Zero area: all vertices on one point.
        let mut dot = quad(0.0);
        for v in 0..4 {
            dot.px[v] = 0.0;
            dot.pz[v] = 0.0;
        }
        assert!(mesh_plane(&dot).is_none());
        let mut nan = quad(0.0);
        nan.px[1] = f32::NAN;
        assert!(mesh_plane(&nan).is_none());
    }

    #[test]
    fn coplanar_instances_share_a_plane_and_lights_below_are_not_clear() {
        let mut scene = Scene::empty("planes");
        let m = scene.add_mesh(quad(0.0));
        let xs = [
            Affine3A::from_translation(Vec3::new(0.0, 0.0, 0.0)),
            Affine3A::from_translation(Vec3::new(5.0, 0.0, -3.0)),
            // Rotated about the plane's normal and scaled: still the plane y = 0.
            Affine3A::from_scale_rotation_translation(Vec3::splat(2.0), glam::Quat::from_rotation_y(0.7), Vec3::new(-4.0, 0.0, 1.0)),
            // Lifted: another plane.
            Affine3A::from_translation(Vec3::new(0.0, 1.0, 0.0)),
            // Tilted: another plane.
            Affine3A::from_rotation_x(0.3),
        ];
        let leaves: Vec<MLeaf> =
            xs.iter().map(|x| MLeaf { tree: 0, mesh: m, xform: *x, inv: x.inverse(), normal_mat: normal_mat(x), material: None }).collect();
        let fp = FlatPlanes::build(&scene, &leaves, &Tlas::default());
        assert_eq!(fp.leaf[0], fp.leaf[1]);
        assert_eq!(fp.leaf[0], fp.leaf[2]);
        assert_ne!(fp.leaf[0], fp.leaf[3]);
        assert_ne!(fp.leaf[0], fp.leaf[4]);
        assert_ne!(fp.leaf[3], fp.leaf[4]);
        assert!(fp.leaf.iter().all(|&k| k != NONE));
        let id = fp.leaf[0];
        let up = Vec3::Y;
        // A point light above, seen from above: clear. Below, or seen from below: not.
        assert!(fp.light_clear(id, up, Vec3::new(3.0, 4.0, 0.0), Vec3::ZERO, Vec3::ZERO));
        assert!(!fp.light_clear(id, up, Vec3::new(3.0, -4.0, 0.0), Vec3::ZERO, Vec3::ZERO));
        assert!(!fp.light_clear(id, -up, Vec3::new(3.0, 4.0, 0.0), Vec3::ZERO, Vec3::ZERO));
        assert!(fp.light_clear(id, -up, Vec3::new(3.0, -4.0, 0.0), Vec3::ZERO, Vec3::ZERO));
        // An elliptical light that dips through the plane is not clear; one above it is.
        assert!(!fp.light_clear(id, up, Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 1.5, 0.0), Vec3::X));
        assert!(fp.light_clear(id, up, Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.0, 1.5, 0.0), Vec3::X));
        // A light in the plane is not clear, nor a fragment whose normal is not the plane's.
        assert!(!fp.light_clear(id, up, Vec3::new(9.0, 0.0, 0.0), Vec3::ZERO, Vec3::ZERO));
        assert!(!fp.light_clear(id, Vec3::X, Vec3::new(3.0, 4.0, 0.0), Vec3::ZERO, Vec3::ZERO));
        assert!(!fp.light_clear(NONE, up, Vec3::new(3.0, 4.0, 0.0), Vec3::ZERO, Vec3::ZERO));
    }
}
