//! Watertight ray–triangle intersection (Woop, Benthin & Wald, JCGT 2013), the scalar
//! reference used by the obvhs back-end. Shearing the triangle into ray space makes the
//! edge tests consistent between neighbouring triangles: a ray through a shared edge or
//! vertex hits at least one of them, which the watertightness tests check. The hit distance
//! comes from the triangle's plane, as in Embree (see `plane_t`).

use glam::Vec3;

/// Per-ray precomputation: the dominant axis permutation and shear, stored as the two rows
/// of the ray-space matrix that the edge functions use (`x' = mx·p`, `y' = my·p` for `p`
/// relative to the origin), and the direction for the hit distance (`plane_t`). Each row
/// has one zero, so its dot product is bit-identical to the paper's `p[kx] − sx·p[kz]` (a
/// sum with one exact zero term does not depend on its order), without indexing vectors by a
/// run-time axis.
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    pub org: Vec3,
    dir: Vec3,
    mx: Vec3,
    my: Vec3,
}

/// The watertight test's axes: kz the dominant axis of `dir`, (kx, ky) the other two, swapped
/// when `dir[kz] < 0` so the triangle's winding is preserved.
#[inline(always)]
fn axis_permutation(dir: Vec3) -> (usize, usize, usize) {
    let a = dir.abs();
    let kz = if a.x > a.y {
        if a.x > a.z {
            0
        } else {
            2
        }
    } else if a.y > a.z {
        1
    } else {
        2
    };
    let (kx, ky) = ((kz + 1) % 3, (kz + 2) % 3);
    if dir[kz] < 0.0 {
        (ky, kx, kz)
    } else {
        (kx, ky, kz)
    }
}

impl RayShear {
    #[inline(always)]
    pub fn new(org: Vec3, dir: Vec3) -> Self {
        let (kx, ky, kz) = axis_permutation(dir);
        let (sx, sy) = (dir[kx] / dir[kz], dir[ky] / dir[kz]);
        let mut mx = Vec3::ZERO;
        mx[kx] = 1.0;
        mx[kz] = -sx;
        let mut my = Vec3::ZERO;
        my[ky] = 1.0;
        my[kz] = -sy;
        RayShear { org, dir, mx, my }
    }
}

/// Returns (t, u, v) with u the weight of v1 and v of v2 (Embree's convention), for hits with
/// tnear ≤ t ≤ tfar.
#[inline(always)]
pub fn intersect_watertight(s: &RayShear, v0: Vec3, v1: Vec3, v2: Vec3, tnear: f32, tfar: f32) -> Option<(f32, f32, f32)> {
    let a = v0 - s.org;
    let b = v1 - s.org;
    let c = v2 - s.org;
    let (ax, ay) = (s.mx.dot(a), s.my.dot(a));
    let (bx, by) = (s.mx.dot(b), s.my.dot(b));
    let (cx, cy) = (s.mx.dot(c), s.my.dot(c));
    let (_, v, w, det) = edge_functions([ax, ay, bx, by, cx, cy])?;
    let t = plane_t(a, b, c, s.dir);
    if !(t >= tnear && t <= tfar) {
        return None;
    }
    let inv = 1.0 / det;
    Some((t, v * inv, w * inv))
}

/// Distance along `dir` to the plane of the origin-relative vertices (a, b, c), from the
/// geometric normal as Embree computes it (`T = dot(v0, Ng) / dot(Ng, dir)`), not from the
/// barycentric-weighted vertex depths of Woop et al.: for a sliver (a triangle 1e-7 wide)
/// the f32 edge functions carry errors as large as themselves, and the weighted depths put
/// the hit anywhere between the vertices' depths (t 0.949 instead of 1.0 on a flat sliver,
/// `lodtrace verify`). The hit/miss decision stays with the watertight edge functions.
#[inline(always)]
fn plane_t(a: Vec3, b: Vec3, c: Vec3, dir: Vec3) -> f32 {
    let n = (b - a).cross(c - a);
    n.dot(a) / n.dot(dir)
}

/// The 2-D part of the watertight test on the sheared vertices `[ax, ay, bx, by, cx, cy]`:
/// the edge functions (u, v, w) with the double-precision fallback on an edge (the paper's
/// recommendation) and their sum, or None when the ray misses or the triangle is degenerate.
#[inline(always)]
fn edge_functions([ax, ay, bx, by, cx, cy]: [f32; 6]) -> Option<(f32, f32, f32, f32)> {
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    if u == 0.0 || v == 0.0 || w == 0.0 {
        u = (cx as f64 * by as f64 - cy as f64 * bx as f64) as f32;
        v = (ax as f64 * cy as f64 - ay as f64 * cx as f64) as f32;
        w = (bx as f64 * ay as f64 - by as f64 * ax as f64) as f32;
    }
    if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
        return None;
    }
    let det = u + v + w;
    if det == 0.0 || !det.is_finite() {
        return None;
    }
    Some((u, v, w, det))
}

/// Möller–Trumbore, kept as a second reference for tests (not watertight).
pub fn intersect_moller_trumbore(org: Vec3, dir: Vec3, v0: Vec3, v1: Vec3, v2: Vec3) -> Option<(f32, f32, f32)> {
    let e1 = v1 - v0;
    let e2 = v2 - v0;
    let p = dir.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let s = org - v0;
    let u = s.dot(p) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    Some((e2.dot(q) * inv, u, v))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    #[test]
    fn agrees_with_moller_trumbore_away_from_edges() {
        let mut s = Sampler::new(3, 0, 0);
        let mut r = || s.next() * 2.0 - 1.0;
        let mut agree = 0;
        for _ in 0..20000 {
            let v0 = Vec3::new(r(), r(), r());
            let v1 = Vec3::new(r(), r(), r());
            let v2 = Vec3::new(r(), r(), r());
            let org = Vec3::new(r(), r(), r()) * 3.0;
            let dir = Vec3::new(r(), r(), r());
            let a = intersect_watertight(&RayShear::new(org, dir), v0, v1, v2, f32::NEG_INFINITY, f32::INFINITY);
            let b = intersect_moller_trumbore(org, dir, v0, v1, v2);
            match (a, b) {
                (Some(a), Some(b)) => {
                    assert!((a.0 - b.0).abs() <= 1e-3 * (1.0 + b.0.abs()), "{a:?} {b:?}");
                    assert!((a.1 - b.1).abs() < 1e-3 && (a.2 - b.2).abs() < 1e-3);
                    agree += 1;
                }
                (None, None) => agree += 1,
                (Some(h), None) | (None, Some(h)) => {
                    // Only near an edge may they disagree.
                    let w = 1.0 - h.1 - h.2;
                    assert!(h.1.min(h.2).min(w).abs() < 1e-3, "disagreement away from an edge: {h:?}");
                }
            }
        }
        assert!(agree > 19900);
    }

    /// The paper's formulation, indexing the vertices by the ray's axis permutation, as the
    /// reference for the matrix-row shear of [`RayShear`].
    fn watertight_indexed(org: Vec3, dir: Vec3, v: [Vec3; 3]) -> Option<(f32, f32, f32)> {
        let (kx, ky, kz) = axis_permutation(dir);
        let (sx, sy) = (dir[kx] / dir[kz], dir[ky] / dir[kz]);
        let [a, b, c] = v.map(|p| p - org);
        // The shear indexed by axis; the shared 2-D part is not what this test is about.
        let sheared =
            [a[kx] - sx * a[kz], a[ky] - sy * a[kz], b[kx] - sx * b[kz], b[ky] - sy * b[kz], c[kx] - sx * c[kz], c[ky] - sy * c[kz]];
        let (_, v, w, det) = edge_functions(sheared)?;
        let t = plane_t(a, b, c, dir);
        (t >= 0.0).then(|| (t, v * (1.0 / det), w * (1.0 / det)))
    }

    #[test]
    fn matrix_shear_is_bit_identical_to_indexed_reference() {
        let mut s = Sampler::new(4, 0, 0);
        let mut r = || s.next() * 2.0 - 1.0;
        let mut hits = 0;
        for k in 0..50000 {
            let v = [Vec3::new(r(), r(), r()), Vec3::new(r(), r(), r()), Vec3::new(r(), r(), r())];
            let org = Vec3::new(r(), r(), r()) * 3.0;
            // Mostly aimed near the triangle (so that many rays hit), some random.
            let aim = (v[0] + v[1] + v[2]) / 3.0 + Vec3::new(r(), r(), r()) * 0.3;
            let mut dir = if k % 3 == 0 { Vec3::new(r(), r(), r()) } else { aim - org };
            // Axis-aligned and negative-axis directions exercise every permutation and swap.
            if k % 7 == 0 {
                dir = Vec3::new(0.0, 0.0, r().signum());
            }
            let ours = intersect_watertight(&RayShear::new(org, dir), v[0], v[1], v[2], 0.0, f32::INFINITY);
            let reference = watertight_indexed(org, dir, v);
            let bits = |h: Option<(f32, f32, f32)>| h.map(|(t, u, w)| (t.to_bits(), u.to_bits(), w.to_bits()));
            assert_eq!(bits(ours), bits(reference), "ray {org:?} {dir:?} tri {v:?}");
            hits += ours.is_some() as u32;
        }
        assert!(hits > 10000, "too few hits to mean anything: {hits}");
    }

    /// Hits on slivers (flat triangles 1e-7 to 1e-5 wide in the plane z = 0) lie on their
    /// plane: the distance comes from the plane, not from the slivers' f32 barycentrics
    /// (which put the hit up to 5 % of the way off along the ray).
    #[test]
    fn sliver_hits_lie_on_their_plane() {
        let mut s = Sampler::new(5, 0, 0);
        let mut r = || s.next();
        let mut hits = 0;
        for _ in 0..20000 {
            let w = 10f32.powf(-7.0 + 2.0 * r());
            let v = [Vec3::new(0.0, 1.0, 0.0), Vec3::ZERO, Vec3::new(w, w, 0.0)];
            let aim = Vec3::new(w * r(), r(), 0.0);
            let org = aim + Vec3::new(r() - 0.5, r() - 0.5, -0.1 - r());
            let dir = aim - org;
            if let Some((t, _, _)) = intersect_watertight(&RayShear::new(org, dir), v[0], v[1], v[2], 0.0, f32::INFINITY) {
                let z = org.z + t * dir.z;
                assert!(z.abs() < 1e-6, "hit {z} off the plane (t {t}, w {w})");
                hits += 1;
            }
        }
        assert!(hits > 1000, "too few hits to mean anything: {hits}");
    }

    #[test]
    fn shared_edge_is_hit_by_one_side() {
        // Two triangles sharing the diagonal of the unit square; rays exactly on the diagonal.
        let p = [Vec3::new(0.0, 0.0, 0.0), Vec3::new(1.0, 0.0, 0.0), Vec3::new(1.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 0.0)];
        for k in 0..=100 {
            let x = k as f32 / 100.0;
            let s = RayShear::new(Vec3::new(x, x, 1.0), Vec3::new(0.0, 0.0, -1.0));
            let a = intersect_watertight(&s, p[0], p[1], p[2], 0.0, f32::INFINITY);
            let b = intersect_watertight(&s, p[0], p[2], p[3], 0.0, f32::INFINITY);
            assert!(a.is_some() || b.is_some(), "ray on the shared edge at {x} fell through");
        }
    }
}
