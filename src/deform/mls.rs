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
//! *Deviation:* the caller's support h is the surfel's rest support times its local stretch
//! (clamped to [1, 3], `TraceParams::max_support_stretch`; 1 = the paper's fixed support).

use super::displace::spline_weight;
use glam::Vec3;
use wide::f32x8;

/// Most neighbours an MLS neighbourhood holds (`ObjectParams::mls_neighbours` ≤ 32).
pub const MAX_NBR: usize = 32;

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
    let w = c - o;
    let t = n.dot(w) / den;
    if !(t >= tnear && t <= tfar) {
        return None;
    }
    let x = o + d * t;
    // The offset from the centre as d·t − (c − o), not x − c: far from the origin x's own
    // rounding (ulp of |x|) would exceed a small splat's size (review finding, stop 49).
    let q = d * t - w;
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
/// neighbours (position, unit normal); `(sc, sr)` is the leaf sphere that bounds every point
/// the iteration moves to (the start point itself, on the leaf's ellipse, is not checked).
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
        match step(it, sw, sa, sn, (x, t), (o, d), (sc, sr), (tnear, tfar), eps) {
            Ok(next) => (x, t) = next,
            Err(done) => return done,
        }
    }
    MlsOutcome::Rejected { iters: prm.max_iter }
}

/// One MLS update from the weighted sums at the current point (x, t): converged (a hit),
/// rejected, or the next point — the ray's hit with the plane (n(x), a(x)).
#[allow(clippy::too_many_arguments)]
#[inline(always)]
fn step(
    it: u32,
    sw: f32,
    sa: Vec3,
    sn: Vec3,
    (x, t): (Vec3, f32),
    (o, d): (Vec3, Vec3),
    (sc, sr): (Vec3, f32),
    (tnear, tfar): (f32, f32),
    eps: f32,
) -> Result<(Vec3, f32), MlsOutcome> {
    let ln = sn.length();
    if !(sw > 0.0) || !(ln > 0.0) || !ln.is_finite() {
        return Err(MlsOutcome::Rejected { iters: it });
    }
    let a = sa / sw;
    let n = sn / ln;
    let f = n.dot(x - a);
    if f.abs() < eps {
        return Err(MlsOutcome::Hit { t, p: x, n, iters: it });
    }
    let den = n.dot(d);
    if den.abs() < 1e-7 * d.length() {
        return Err(MlsOutcome::Rejected { iters: it });
    }
    let t = n.dot(a - o) / den;
    let x = o + d * t;
    if !(t >= tnear && t <= tfar && x.is_finite()) || (x - sc).length_squared() > sr * sr {
        return Err(MlsOutcome::Rejected { iters: it });
    }
    Ok((x, t))
}

/// An MLS neighbourhood in struct-of-arrays form for [`mls_intersect_x8`]: positions and
/// unit normals, padded to a multiple of 8 lanes with far-away points (weight 0).
#[derive(Clone, Debug)]
pub struct MlsNbr {
    p: [[f32; MAX_NBR]; 3],
    n: [[f32; MAX_NBR]; 3],
    len: usize,
}

/// Position of the padding lanes: far beyond any support, yet its squared distance to any
/// finite point of a scene stays finite in f32.
const PAD: f32 = 1e18;

impl Default for MlsNbr {
    fn default() -> Self {
        MlsNbr { p: [[PAD; MAX_NBR]; 3], n: [[0.0; MAX_NBR]; 3], len: 0 }
    }
}

impl MlsNbr {
    /// Empties the neighbourhood (keeps the padding invariant).
    #[inline]
    pub fn clear(&mut self) {
        for a in 0..3 {
            self.p[a][..self.len].fill(PAD);
            self.n[a][..self.len].fill(0.0);
        }
        self.len = 0;
    }
    /// Adds a neighbour (at most [`MAX_NBR`]).
    #[inline]
    pub fn push(&mut self, p: Vec3, n: Vec3) {
        let i = self.len;
        assert!(i < MAX_NBR, "MLS neighbourhood full");
        // Component by component: a loop over `p[a]` went through glam's checked index,
        // about 25 instructions a neighbour against 8 (16 neighbours per MLS run).
        [self.p[0][i], self.p[1][i], self.p[2][i]] = p.to_array();
        [self.n[0][i], self.n[1][i], self.n[2][i]] = n.to_array();
        self.len = i + 1;
    }
    pub fn len(&self) -> usize {
        self.len
    }
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }
}

/// [`mls_intersect`] with the weighted sums over the neighbourhood 8 lanes at a time (16
/// neighbours: two f32x8 steps per iteration). The same iteration and rejection rules; the
/// sums are added in another order, so results agree with the scalar reference to rounding
/// (`x8_matches_scalar`): the same points to a few ε; near the convergence threshold one may
/// take one step more than the other, and rarely (≤ 3 of its 3,000 cases) a borderline
/// iteration is accepted by one and rejected by the other. The tracer uses only this one,
/// so its paths agree bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn mls_intersect_x8(
    o: Vec3,
    d: Vec3,
    t0: f32,
    x0: Vec3,
    nb: &MlsNbr,
    h: f32,
    sc: Vec3,
    sr: f32,
    tnear: f32,
    tfar: f32,
    prm: &MlsParams,
) -> MlsOutcome {
    let mut x = x0;
    let mut t = t0;
    let inv_h = f32x8::splat(1.0 / h);
    let eps = prm.eps_rel * h;
    let chunks = nb.len.div_ceil(8);
    let (one, zero) = (f32x8::splat(1.0), f32x8::splat(0.0));
    let load = |a: &[f32; MAX_NBR], c: usize| f32x8::from(<[f32; 8]>::try_from(&a[8 * c..8 * c + 8]).unwrap());
    for it in 1..=prm.max_iter {
        let (xx, xy, xz) = (f32x8::splat(x.x), f32x8::splat(x.y), f32x8::splat(x.z));
        let (mut sw, mut sax, mut say, mut saz, mut snx, mut sny, mut snz) = (zero, zero, zero, zero, zero, zero, zero);
        for c in 0..chunks {
            let (px, py, pz) = (load(&nb.p[0], c), load(&nb.p[1], c), load(&nb.p[2], c));
            let (dx, dy, dz) = (xx - px, xy - py, xz - pz);
            let r = (dx * dx + dy * dy + dz * dz).sqrt() * inv_h;
            // Eq. 2 as `spline_weight` evaluates it, (1 − r)³(1 + 3r).
            let s = one - r;
            let poly = s * s * s * (one + f32x8::splat(3.0) * r);
            let w = r.simd_lt(one).bitselect(poly, zero);
            sw += w;
            sax += px * w;
            say += py * w;
            saz += pz * w;
            snx += load(&nb.n[0], c) * w;
            sny += load(&nb.n[1], c) * w;
            snz += load(&nb.n[2], c) * w;
        }
        let sw = sw.reduce_add();
        let sa = Vec3::new(sax.reduce_add(), say.reduce_add(), saz.reduce_add());
        let sn = Vec3::new(snx.reduce_add(), sny.reduce_add(), snz.reduce_add());
        match step(it, sw, sa, sn, (x, t), (o, d), (sc, sr), (tnear, tfar), eps) {
            Ok(next) => (x, t) = next,
            Err(done) => return done,
        }
    }
    MlsOutcome::Rejected { iters: prm.max_iter }
}

/// Clipping classification (§4.3, after \[WTG04\]) of point `x` against a surface represented
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

    /// The x8 iteration against the scalar reference: noisy sampled spheres seen from random
    /// rays, every neighbourhood size from 3 to 32 (padding lanes), hits and rejections.
    #[test]
    fn x8_matches_scalar() {
        use crate::core::rng::Sampler;
        let mut s = Sampler::new(3, 9, 27);
        let (mut hits, mut rejects, mut differ, mut steps_differ) = (0, 0, 0u32, 0u32);
        for case in 0..3000 {
            let k = 3 + case % 30;
            let c = Vec3::new(s.next(), s.next(), s.next()) * 4.0 - 2.0;
            let rad = 0.3 + s.next();
            let mut nb = Vec::new();
            let mut nbx = MlsNbr::default();
            let dir0 = Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize_or(Vec3::Z);
            for _ in 0..k {
                let q = (dir0 + Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.4).normalize_or(Vec3::Z);
                let p = c + q * rad * (1.0 + 0.01 * (s.next() - 0.5));
                nb.push((p, q));
                nbx.push(p, q);
            }
            let x0 = c + dir0 * rad;
            let o = x0 + Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.2 + dir0 * 3.0;
            let d = (x0 - o).normalize() * (0.5 + s.next());
            let t0 = (x0 - o).length() / d.length();
            // Some cases must be rejected: a tiny leaf sphere (the first step leaves it) or a
            // support too small to reach any neighbour.
            let h = rad * if case % 11 == 0 { 1e-4 } else { 0.3 + 0.5 * s.next() };
            let sr = rad * if case % 7 == 0 { 1e-5 } else { 0.6 };
            let prm = MlsParams::default();
            let a = mls_intersect(o, d, t0, x0, &nb, h, x0, sr, 0.0, 100.0, &prm);
            let b = mls_intersect_x8(o, d, t0, x0, &nbx, h, x0, sr, 0.0, 100.0, &prm);
            // Near the threshold one side may need one more step; the point then differs by
            // about ε. A different outcome (a borderline rejection) must stay rare.
            let eps = prm.eps_rel * h;
            match (a, b) {
                (MlsOutcome::Hit { p: pa, n: na, iters: ia, .. }, MlsOutcome::Hit { p: pb, n: nb2, iters: ib, .. }) => {
                    assert!(
                        (pa - pb).length() <= 4.0 * eps && (na - nb2).length() < 1e-3 && ia.abs_diff(ib) <= 1,
                        "case {case}: {a:?} vs {b:?}"
                    );
                    hits += 1;
                    steps_differ += (ia != ib) as u32;
                }
                (MlsOutcome::Rejected { iters: ia }, MlsOutcome::Rejected { iters: ib }) => {
                    assert!(ia.abs_diff(ib) <= 1, "case {case}");
                    rejects += 1;
                }
                _ => differ += 1,
            }
            nbx.clear();
            assert!(nbx.is_empty());
        }
        assert!(hits > 1000 && rejects > 50, "{hits} hits, {rejects} rejections");
        assert!(differ <= 3 && steps_differ <= 30, "{differ} outcomes and {steps_differ} step counts differ");
    }

    #[test]
    fn clip_rule() {
        // Convex edge of the solid {z < 0, x < 0}.
        let (p1, n1, p2, n2) = (Vec3::new(-0.1, 0.0, 0.0), Vec3::Z, Vec3::new(0.0, 0.0, -0.1), Vec3::X);
        assert!(!clipped_by(Vec3::new(-0.5, 0.0, -0.5), p1, n1, p2, n2));
        assert!(clipped_by(Vec3::new(0.5, 0.0, -0.5), p1, n1, p2, n2));
        assert!(clipped_by(Vec3::new(-0.5, 0.0, 0.5), p1, n1, p2, n2));
        assert!(clipped_by(Vec3::new(0.5, 0.0, 0.5), p1, n1, p2, n2));
        // Concave edge of the L-shaped solid {z < 0} ∪ {x < 0} (its complement is the convex
        // quadrant x > 0, z > 0): a point under one of the two planes is inside, whatever the
        // other says; only the quadrant is outside.
        let (p1, n1, p2, n2) = (Vec3::new(0.1, 0.0, 0.0), Vec3::Z, Vec3::new(0.0, 0.0, 0.1), Vec3::X);
        assert!(!clipped_by(Vec3::new(0.5, 0.0, -0.5), p1, n1, p2, n2));
        assert!(!clipped_by(Vec3::new(-0.5, 0.0, 0.5), p1, n1, p2, n2));
        assert!(!clipped_by(Vec3::new(-0.5, 0.0, -0.5), p1, n1, p2, n2));
        assert!(clipped_by(Vec3::new(0.5, 0.0, 0.5), p1, n1, p2, n2));
    }

    /// A converged hit satisfies the paper's criterion |n(x)ᵀ(x − a(x))| < ε at the point it
    /// returns (re-evaluated here from the neighbourhood, independently of `step`), on curved
    /// neighbourhoods where the first step does not converge.
    #[test]
    fn hits_meet_the_convergence_criterion() {
        use crate::core::rng::Sampler;
        let mut s = Sampler::new(5, 1, 2);
        let prm = MlsParams::default();
        let (mut hits, mut multi_step) = (0, 0);
        for _ in 0..2000 {
            let c = Vec3::new(s.next(), s.next(), s.next()) * 2.0 - 1.0;
            let rad = 0.3 + s.next();
            let dir0 = Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize_or(Vec3::Z);
            let nb: Vec<(Vec3, Vec3)> = (0..16)
                .map(|_| {
                    let q = (dir0 + Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.6).normalize_or(Vec3::Z);
                    (c + q * rad, q)
                })
                .collect();
            // Start off the surface (a surfel disc is tangent, the sphere curves away).
            let x0 = c + dir0 * rad * 1.05;
            let o = x0 + dir0 * 3.0 + Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5) * 0.3;
            let d = (x0 - o).normalize();
            let t0 = (x0 - o).length();
            let h = rad * (0.4 + 0.4 * s.next());
            if let MlsOutcome::Hit { t, p, n, iters } = mls_intersect(o, d, t0, x0, &nb, h, x0, rad, 0.0, 100.0, &prm) {
                let (mut sw, mut sa, mut sn) = (0.0f32, Vec3::ZERO, Vec3::ZERO);
                for &(q, m) in &nb {
                    let w = spline_weight((p - q).length() / h);
                    (sw, sa, sn) = (sw + w, sa + q * w, sn + m * w);
                }
                let f = sn.normalize().dot(p - sa / sw);
                assert!(f.abs() < prm.eps_rel * h, "residual {f} ≥ ε = {}", prm.eps_rel * h);
                assert!((o + d * t - p).length() <= 1e-5 * (1.0 + t), "the hit is on the ray");
                assert!((n - sn.normalize()).length() < 1e-4, "the normal is n(x)");
                hits += 1;
                multi_step += (iters > 1) as u32;
            }
        }
        assert!(hits > 1000 && multi_step > 500, "{hits} hits, {multi_step} after more than one step");
    }
}
