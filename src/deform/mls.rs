//! Ray–surface intersection with the MLS point-set surface (Adams et al. §4.2.1, Eq. 12,
//! after Adamson & Alexa [AA03a, AA04]).
//!
//! Start: the ray's hit with the leaf surfel's (deformed) ellipse. Iterate: weighted average
//! position `a(x)` and normal `n(x)` of the static neighbourhood (Eq. 2 weights against the
//! *current* point x, support h); converged when `|n(x)ᵀ(x − a(x))| < ε`; otherwise move x to
//! the ray's intersection with the plane (n(x), a(x)). The point is rejected if it leaves the
//! leaf's sphere, leaves [tnear, tfar], the weights vanish, the plane is parallel to the ray,
//! or the iteration has not converged after `max_iter` steps — a diverging iteration is a
//! miss for this leaf, never a NaN.
//!
//! Choices: ε = `eps_rel · h` (scale-free); the returned normal is n(x) at the converged
//! point (consistently oriented because the surfel normals are).

use super::displace::spline_weight;
use glam::Vec3;

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct MlsParams {
    /// Convergence threshold relative to the MLS support h.
    pub eps_rel: f32,
    /// Iteration limit; not converged by then = rejected.
    pub max_iter: u32,
}

impl Default for MlsParams {
    fn default() -> Self {
        MlsParams { eps_rel: 1e-4, max_iter: 12 }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum MlsOutcome {
    /// Converged inside the sphere: ray parameter, point, unit normal, iterations used.
    Hit { t: f32, p: Vec3, n: Vec3, iters: u32 },
    /// Rejected after `iters` evaluations.
    Rejected { iters: u32 },
}

/// Ray hit with the ellipse (centre `c`, axes `u`, `v`): (t, point), or None.
#[inline]
pub fn ellipse_hit(o: Vec3, d: Vec3, c: Vec3, u: Vec3, v: Vec3, tnear: f32, tfar: f32) -> Option<(f32, Vec3)> {
    let n = u.cross(v);
    let den = n.dot(d);
    if den == 0.0 || !den.is_finite() {
        return None;
    }
    let t = n.dot(c - o) / den;
    if !(t >= tnear && t <= tfar) {
        return None;
    }
    let x = o + d * t;
    let q = x - c;
    // Solve q = α u + β v in the least-squares sense (Gram system).
    let (a, b, cc) = (u.dot(u), u.dot(v), v.dot(v));
    let det = a * cc - b * b;
    if !(det > 0.0) {
        return None;
    }
    let (qu, qv) = (q.dot(u), q.dot(v));
    let al = (cc * qu - b * qv) / det;
    let be = (a * qv - b * qu) / det;
    if al * al + be * be <= 1.0 {
        Some((t, x))
    } else {
        None
    }
}

/// The MLS iteration from the start point `(t0, x0)` on the ray. `nb` are the deformed
/// neighbours (position, unit normal); `(sc, sr)` is the leaf sphere that bounds the result.
#[allow(clippy::too_many_arguments)]
pub fn mls_intersect(
    o: Vec3,
    d: Vec3,
    t0: f32,
    x0: Vec3,
    nb: &[(Vec3, Vec3)],
    h: f32,
    sc: Vec3,
    sr: f32,
    tnear: f32,
    tfar: f32,
    prm: &MlsParams,
) -> MlsOutcome {
    let mut x = x0;
    let mut t = t0;
    let inv_h = 1.0 / h;
    let eps = prm.eps_rel * h;
    for it in 1..=prm.max_iter {
        let mut sw = 0.0f32;
        let mut sa = Vec3::ZERO;
        let mut sn = Vec3::ZERO;
        for &(p, n) in nb {
            let w = spline_weight((x - p).length() * inv_h);
            sw += w;
            sa += p * w;
            sn += n * w;
        }
        let ln = sn.length();
        if !(sw > 0.0) || !(ln > 0.0) || !ln.is_finite() {
            return MlsOutcome::Rejected { iters: it };
        }
        let a = sa / sw;
        let n = sn / ln;
        let f = n.dot(x - a);
        if f.abs() < eps {
            return MlsOutcome::Hit { t, p: x, n, iters: it };
        }
        let den = n.dot(d);
        if den.abs() < 1e-7 * d.length() {
            return MlsOutcome::Rejected { iters: it };
        }
        t = n.dot(a - o) / den;
        x = o + d * t;
        if !(t >= tnear && t <= tfar) || !x.is_finite() || (x - sc).length_squared() > sr * sr {
            return MlsOutcome::Rejected { iters: it };
        }
    }
    MlsOutcome::Rejected { iters: prm.max_iter }
}

/// Clipping classification (§4.3, after [WTG04]) of point `x` against a surface represented
/// locally by its two nearest surfels (p1, n1), (p2, n2) (normals point out of the solid):
/// true if x lies outside. Where the signed distances disagree, a convex pair (each surfel
/// behind the other's plane) bounds the intersection of the two half-spaces, a concave pair
/// their union.
#[inline]
pub fn clipped_by(x: Vec3, p1: Vec3, n1: Vec3, p2: Vec3, n2: Vec3) -> bool {
    let d1 = n1.dot(x - p1);
    let d2 = n2.dot(x - p2);
    if (d1 > 0.0) == (d2 > 0.0) {
        return d1 > 0.0;
    }
    let convex = n1.dot(p2 - p1) <= 0.0 && n2.dot(p1 - p2) <= 0.0;
    if convex {
        true // outside either half-space of a convex edge: outside
    } else {
        false // inside one half-space of a concave edge: inside
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ellipse_and_plane() {
        let c = Vec3::new(0.0, 0.0, 1.0);
        let (u, v) = (Vec3::X * 0.5, Vec3::Y * 0.25);
        assert!(ellipse_hit(Vec3::ZERO, Vec3::Z, c, u, v, 0.0, 10.0).is_some());
        assert!(ellipse_hit(Vec3::new(0.4, 0.0, 0.0), Vec3::Z, c, u, v, 0.0, 10.0).is_some());
        assert!(ellipse_hit(Vec3::new(0.0, 0.3, 0.0), Vec3::Z, c, u, v, 0.0, 10.0).is_none());
        assert!(ellipse_hit(Vec3::ZERO, Vec3::Z, c, u, v, 0.0, 0.5).is_none());
        // Flat neighbourhood: converges at once onto the plane z = 1.
        let nb: Vec<(Vec3, Vec3)> =
            (0..16).map(|i| (Vec3::new((i % 4) as f32 * 0.2 - 0.3, (i / 4) as f32 * 0.2 - 0.3, 1.0), Vec3::Z)).collect();
        let o = Vec3::new(0.05, 0.02, 0.0);
        let (t0, x0) = ellipse_hit(o, Vec3::Z, c, u, v, 0.0, 10.0).unwrap();
        match mls_intersect(o, Vec3::Z, t0, x0, &nb, 0.8, c, 0.6, 0.0, 10.0, &MlsParams::default()) {
            MlsOutcome::Hit { t, n, iters, .. } => {
                assert!((t - 1.0).abs() < 1e-5 && (n - Vec3::Z).length() < 1e-5 && iters == 1)
            }
            r => panic!("{r:?}"),
        }
        // No neighbour in reach: rejected, not NaN.
        let far: Vec<(Vec3, Vec3)> = vec![(Vec3::splat(100.0), Vec3::Z); 4];
        assert!(matches!(
            mls_intersect(o, Vec3::Z, t0, x0, &far, 0.8, c, 0.6, 0.0, 10.0, &MlsParams::default()),
            MlsOutcome::Rejected { .. }
        ));
    }

    #[test]
    fn clip_rule() {
        // Convex edge of the solid {z < 0, x < 0}.
        let (p1, n1, p2, n2) = (Vec3::new(-0.1, 0.0, 0.0), Vec3::Z, Vec3::new(0.0, 0.0, -0.1), Vec3::X);
        assert!(!clipped_by(Vec3::new(-0.5, 0.0, -0.5), p1, n1, p2, n2));
        assert!(clipped_by(Vec3::new(0.5, 0.0, -0.5), p1, n1, p2, n2));
        assert!(clipped_by(Vec3::new(-0.5, 0.0, 0.5), p1, n1, p2, n2));
    }
}
