//! Watertight ray–triangle intersection (Woop, Benthin & Wald, JCGT 2013), the scalar
//! reference used by the obvhs back-end. Shearing the triangle into ray space makes the
//! edge tests consistent between neighbouring triangles: a ray through a shared edge or
//! vertex hits at least one of them, which the watertightness tests check.

use glam::Vec3;

/// Per-ray precomputation: the dominant axis permutation and shear.
#[derive(Clone, Copy, Debug)]
pub struct RayShear {
    pub org: Vec3,
    kx: usize,
    ky: usize,
    kz: usize,
    sx: f32,
    sy: f32,
    sz: f32,
}

impl RayShear {
    #[inline]
    pub fn new(org: Vec3, dir: Vec3) -> Self {
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
        let mut kx = (kz + 1) % 3;
        let mut ky = (kx + 1) % 3;
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        RayShear { org, kx, ky, kz, sx: dir[kx] / dir[kz], sy: dir[ky] / dir[kz], sz: 1.0 / dir[kz] }
    }
}

/// Returns (t, u, v) with u the weight of v1 and v of v2 (Embree's convention), for hits with
/// tnear ≤ t ≤ tfar.
#[inline(always)]
pub fn intersect_watertight(s: &RayShear, v0: Vec3, v1: Vec3, v2: Vec3, tnear: f32, tfar: f32) -> Option<(f32, f32, f32)> {
    let a = v0 - s.org;
    let b = v1 - s.org;
    let c = v2 - s.org;
    let (kx, ky, kz) = (s.kx, s.ky, s.kz);
    let ax = a[kx] - s.sx * a[kz];
    let ay = a[ky] - s.sy * a[kz];
    let bx = b[kx] - s.sx * b[kz];
    let by = b[ky] - s.sy * b[kz];
    let cx = c[kx] - s.sx * c[kz];
    let cy = c[ky] - s.sy * c[kz];
    let mut u = cx * by - cy * bx;
    let mut v = ax * cy - ay * cx;
    let mut w = bx * ay - by * ax;
    // Fall back to double precision on edges (the paper's recommendation).
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
    let az = s.sz * a[kz];
    let bz = s.sz * b[kz];
    let cz = s.sz * c[kz];
    let t_scaled = u * az + v * bz + w * cz;
    let inv = 1.0 / det;
    let t = t_scaled * inv;
    if !(t >= tnear && t <= tfar) {
        return None;
    }
    Some((t, v * inv, w * inv))
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
