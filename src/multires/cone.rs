//! Ray cones (Wand & Straßer §4.1–4.2).
//!
//! A cone has a frame (origin s_r, unit direction n_r, tangents u_r, v_r) and a footprint
//! fp(t) = startDev + t·incrDev (eq. 1), whose columns span the footprint ellipse in (u_r, v_r)
//! coordinates. The Gaussian filter is exp(−|fp(t)⁻¹(u,v)|²) (eq. 2).
//!
//! Representation: we keep the *squared* footprint Σ(t) = Σₖ fpₖ(t)·fpₖ(t)ᵀ = a + b·t + c·t²
//! (three symmetric 2×2 matrices), because (i) the paper convolves footprints by adding their
//! squares (shadow cones, §4.2), which is then a plain sum, (ii) the eigen-decomposition of
//! Σ gives the ellipse axes directly (eq. 3: fp⁻² = Uᵀ diag(λ²) U, with λ = 1/semi-axis), and
//! (iii) Σ is defined and finite where fp is singular (zero footprint at the origin or at the
//! focal plane). A cone built from one (startDev, incrDev) pair is exactly the paper's.
//!
//! Construction, as in §4.2:
//! - primary: zero startDev, incrDev = the pixel's extent (the derivative of the DESIGN.md
//!   camera direction per pixel), scaled by `cone_scale` (1 = the pixel size). Depth of field:
//!   a second pair with startDev = the lens radius and footprint zero at the focal plane.
//!   *Deviation (stop 40, `--lens-scale`):* by default the lens part is the radius × 1/√2, so
//!   that its Gaussian, exp(−x²/a²) of variance a²/2 per axis, has the variance of the thin
//!   lens's uniform disk (R²/4) that distributed ray tracing samples; with the radius itself
//!   (`--lens-scale 1`) a defocused object blurs √2 times too wide.
//!   *Deviation:* the paper takes the maximum of the lens and the pixel cone; we add their
//!   squares (the convolution used for shadow rays), which is smooth, never smaller than the
//!   maximum and at most √2 larger.
//! - shadow: the surface footprint shrinking to zero at the light, plus the light's ellipse
//!   growing from zero at the surface; squares added (§4.2 "Shadow Rays").
//! - reflected/refracted: startDev = the incoming footprint projected along the ray onto the
//!   tangent plane and expressed in the outgoing frame; incrDev = the difference between the
//!   outgoing directions at p + u_fp, p + v_fp (normals from ∇n) and the centre direction.
//!   A cone that is a sum of pairs (depth of field, a rough reflection) also passes on the
//!   spread of its rays through the centre as a second pair ([`Cone::footprint_and_spread`]):
//!   the paper's one-pair construction alone would lose the lens cone at the focal plane.
//!   The refract-or-total-reflection decision is the centre ray's. An axis end whose own ray
//!   is totally reflected (the centre ray refracting near the critical angle) takes the
//!   grazing direction, the limit its refracted rays fan out to; until the ray-cone review it
//!   took the centre direction, so the cone lost its spread where it is largest (the in-plane
//!   spread 1.5 → 1 at 2° from the critical angle: 0.0002 instead of ≈ 0.2 rad). Roughness adds a radial
//!   increment tan(roughness)·I (§6, "Special Effects").
//!   *Deviation (stop 51, `--rough-scale`):* by default that increment is × 1/√2, the same
//!   variance match as the lens: the distributed reference samples the reflection uniformly
//!   in a cap of half-angle `roughness` (about a uniform disk of radius tan(roughness) per unit
//!   distance, variance tan²/4 per axis), the Gaussian of axis a has variance a²/2.
//! - elliptical lights: the shadow cone's light pair is the ellipse's axes × `light_scale`,
//!   by default 1/√2 for the same reason (*deviation, stop 51, `--light-scale`*: the
//!   reference samples the ellipse uniformly; with the axes themselves a penumbra is √2
//!   too wide).

use crate::core::eigen2::{eigen_1, Eigen2, Sym2};
use crate::core::onb;
use crate::scene::camera::CameraFrame;
use glam::{Affine3A, Mat3, Vec2, Vec3};

/// A 2×2 footprint matrix by columns (each a footprint axis in the cone's (u, v) coordinates).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Fp {
    pub c0: Vec2,
    pub c1: Vec2,
}

impl Fp {
    pub const ZERO: Fp = Fp { c0: Vec2::ZERO, c1: Vec2::ZERO };
    pub fn diag(s: f32) -> Fp {
        Fp { c0: Vec2::new(s, 0.0), c1: Vec2::new(0.0, s) }
    }
    pub fn scale(self, k: f32) -> Fp {
        Fp { c0: self.c0 * k, c1: self.c1 * k }
    }
}

/// M·Nᵀ + N·Mᵀ of two footprint matrices (symmetric).
fn sym_prod(m: Fp, n: Fp) -> Sym2 {
    Sym2 {
        a: 2.0 * (m.c0.x * n.c0.x + m.c1.x * n.c1.x),
        b: m.c0.x * n.c0.y + m.c1.x * n.c1.y + n.c0.x * m.c0.y + n.c1.x * m.c1.y,
        c: 2.0 * (m.c0.y * n.c0.y + m.c1.y * n.c1.y),
    }
}

fn sq(m: Fp) -> Sym2 {
    Sym2 { a: m.c0.x * m.c0.x + m.c1.x * m.c1.x, b: m.c0.x * m.c0.y + m.c1.x * m.c1.y, c: m.c0.y * m.c0.y + m.c1.y * m.c1.y }
}

/// T·S·Tᵀ for T given by rows (t0, t1).
fn congruence(s: Sym2, t0: Vec2, t1: Vec2) -> Sym2 {
    let q = |x: Vec2, y: Vec2| x.x * (s.a * y.x + s.b * y.y) + x.y * (s.b * y.x + s.c * y.y);
    Sym2 { a: q(t0, t0), b: q(t0, t1), c: q(t1, t1) }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Cone {
    pub org: Vec3,
    pub dir: Vec3,
    pub u: Vec3,
    pub v: Vec3,
    /// Σ(t) = a + b·t + c·t².
    pub a: Sym2,
    pub b: Sym2,
    pub c: Sym2,
    pub tmin: f32,
    pub tmax: f32,
}

impl Cone {
    /// A cone along unit `dir` with the given (startDev, incrDev) pairs, whose squares add.
    pub fn new(org: Vec3, dir: Vec3, pairs: &[(Fp, Fp)]) -> Cone {
        let (u, v) = onb(dir);
        let mut c = Cone { org, dir, u, v, a: Sym2::default(), b: Sym2::default(), c: Sym2::default(), tmin: 0.0, tmax: f32::INFINITY };
        for &(s, i) in pairs {
            c.a = c.a.add(sq(s));
            c.b = c.b.add(sym_prod(s, i));
            c.c = c.c.add(sq(i));
        }
        c
    }
    /// Footprint matrix columns from 3-D vectors (perpendicular to `dir`) in this frame.
    pub fn fp_of(&self, a: Vec3, b: Vec3) -> Fp {
        Fp { c0: Vec2::new(a.dot(self.u), a.dot(self.v)), c1: Vec2::new(b.dot(self.u), b.dot(self.v)) }
    }
    /// Adds the square of another (startDev, incrDev) pair (convolution, §4.2).
    pub fn add_pair(&mut self, s: Fp, i: Fp) {
        self.a = self.a.add(sq(s));
        self.b = self.b.add(sym_prod(s, i));
        self.c = self.c.add(sq(i));
    }
    /// Σ(t), the squared footprint at parameter t.
    #[inline]
    pub fn sigma(&self, t: f32) -> Sym2 {
        Sym2 {
            a: self.a.a + t * (self.b.a + t * self.c.a),
            b: self.a.b + t * (self.b.b + t * self.c.b),
            c: self.a.c + t * (self.b.c + t * self.c.c),
        }
    }
    /// Σ(t) for 8 depths at once (the packet form of [`Cone::sigma`]).
    #[inline]
    pub fn sigma_x8(&self, t: wide::f32x8) -> (wide::f32x8, wide::f32x8, wide::f32x8) {
        use wide::f32x8 as V;
        let (a, b, c) = (&self.a, &self.b, &self.c);
        (
            V::splat(a.a) + t * (V::splat(b.a) + t * V::splat(c.a)),
            V::splat(a.b) + t * (V::splat(b.b) + t * V::splat(c.b)),
            V::splat(a.c) + t * (V::splat(b.c) + t * V::splat(c.c)),
        )
    }
    /// Ray coordinates (x, y, t) of a point.
    #[inline]
    pub fn coords(&self, p: Vec3) -> Vec3 {
        let d = p - self.org;
        Vec3::new(d.dot(self.u), d.dot(self.v), d.dot(self.dir))
    }
    /// The footprint ellipse at t as two world-space semi-axis vectors (major, minor).
    pub fn footprint_vectors(&self, t: f32, clamp: f32, floor: f32) -> (Vec3, Vec3, Eigen2) {
        let e = eigen_1(self.sigma(t), clamp, floor);
        let (e1, e2) = self.axis_dirs(&e);
        (e1 * e.s1, e2 * e.s2, e)
    }
    /// World-space unit directions of an eigen-decomposition's major and minor axes.
    #[inline]
    fn axis_dirs(&self, e: &Eigen2) -> (Vec3, Vec3) {
        (self.u * e.cos + self.v * e.sin, self.v * e.cos - self.u * e.sin)
    }
    /// The footprint at t, (f0, f1), the direction differentials of the rays through its two
    /// axis ends, (d0, d1), and the spread of the rays through its centre, (x0, x1): the
    /// incoming cone split into two pairs, ([f0 f1], [d0 d1]) and (0, [x0 x1]), whose squares
    /// add up to Σ(t + τ) = Σ(t) + τ·Σ'(t) + τ²·C (C the t² term) for every τ, so that a
    /// surface that only turns the rays (a flat mirror) passes the whole cone on.
    ///
    /// With the footprint's principal axes E = [e₁ e₂] and semi-axes sᵢ = √(eᵢᵀΣeᵢ), the
    /// first pair's directions are E·Y with Y symmetric, Y_ij = eᵢᵀΣ'(t)eⱼ / (sᵢ + sⱼ): then
    /// [f0 f1]·[d0 d1]ᵀ + [d0 d1]·[f0 f1]ᵀ = Σ'(t). Yᵢᵢ = ds/dt along eᵢ (first-order eigenvalue
    /// perturbation); for a one-pair cone without shear Y is exactly incrDev applied to the
    /// axes. The rest of the direction spread, C − E·Y²·Eᵀ (its positive part), is the second
    /// pair's: rays through the centre, uncorrelated with their position. A sum of pairs (the
    /// pixel and lens cones of depth of field, §4.2; a rough reflection's blur) needs it: at
    /// the focal plane the lens cone has no footprint but all its spread. (Until the ray-cone
    /// review only Yᵢᵢ was kept, so a mirror in focus reflected everything in focus, and a
    /// mirror before the focal plane refocused the cone at a false focus: 48–57% too narrow
    /// 10 units on; `flat_mirror_in_focus_keeps_the_lens_blur`.)
    ///
    /// The footprint is the clamped one (the anisotropy clamp inflates the minor axis), the
    /// growth rates those of the cone itself: sᵢ are the unclamped semi-axes. (Until stop 32
    /// the rate was divided by the clamped s₂, which slowed a clamped minor axis's growth by
    /// the clamp's inflation, up to 16×; review finding of stop 31.) eᵀΣ(t)e is a sum of
    /// squares of linear functions of t, so |ds/dt| ≤ √(eᵀCe) exactly: the rates are held to
    /// that bound (the cross rate to the larger of the two), which keeps them finite where s
    /// vanishes.
    pub fn footprint_and_spread(&self, t: f32, clamp: f32, floor: f32) -> [Vec3; 6] {
        let (f0, f1, e) = self.footprint_vectors(t, clamp, floor);
        let sig = self.sigma(t);
        let d = Sym2 { a: self.b.a + 2.0 * t * self.c.a, b: self.b.b + 2.0 * t * self.c.b, c: self.b.c + 2.0 * t * self.c.c };
        // xᵀ·M·y for x = (xc, xs), y = (yc, ys).
        let bil = |m: &Sym2, xc: f32, xs: f32, yc: f32, ys: f32| m.a * xc * yc + m.b * (xc * ys + xs * yc) + m.c * xs * ys;
        let (e1, e2) = ((e.cos, e.sin), (-e.sin, e.cos));
        let size = |x: (f32, f32)| bil(&sig, x.0, x.1, x.0, x.1).max(0.0).sqrt().max(floor);
        let bound = |x: (f32, f32)| bil(&self.c, x.0, x.1, x.0, x.1).max(0.0).sqrt();
        let rate = |x: (f32, f32), y: (f32, f32), lim: f32| {
            let r = bil(&d, x.0, x.1, y.0, y.1) / (size(x) + size(y));
            if r.is_finite() {
                r.clamp(-lim, lim)
            } else {
                0.0
            }
        };
        let y11 = rate(e1, e1, bound(e1));
        let y22 = rate(e2, e2, bound(e2));
        let y12 = rate(e1, e2, bound(e1).max(bound(e2)));
        let (w1, w2) = self.axis_dirs(&e);
        let (d0, d1) = (w1 * y11 + w2 * y12, w1 * y12 + w2 * y22);
        // The centre rays' spread: the positive part of C − (d0 d0ᵀ + d1 d1ᵀ).
        let dd = sq(self.fp_of(d0, d1));
        let rest = Sym2 { a: self.c.a - dd.a, b: self.c.b - dd.b, c: self.c.c - dd.c };
        let (x0, x1) = if rest.is_finite() && rest.a + rest.c > 0.0 {
            let er = eigen_1(rest, 0.0, 0.0);
            let (r1, r2) = self.axis_dirs(&er);
            (r1 * er.s1, r2 * er.s2)
        } else {
            (Vec3::ZERO, Vec3::ZERO)
        };
        [f0, f1, d0, d1, x0, x1]
    }

    /// The primary cone through pixel (i, j) (its centre, as the DESIGN.md camera): its pixel
    /// part scaled by `cone_scale`, its lens part by `lens_scale` (1: the lens radius).
    pub fn primary(cam: &CameraFrame, i: u32, j: u32, cone_scale: f32, lens_scale: f32) -> Cone {
        let (px, py) = (i as f32 + 0.5, j as f32 + 0.5);
        let x = (2.0 * px / cam.width as f32 - 1.0) * cam.aspect * cam.s;
        let y = (1.0 - 2.0 * py / cam.height as f32) * cam.s;
        let d_un = cam.f + x * cam.r + y * cam.u;
        let len = d_un.length();
        let dir = d_un / len;
        // d(dir)/d(pixel) = (dD − dir·(dir·dD)) / |D|
        let dd = |v: Vec3| (v - dir * dir.dot(v)) / len;
        let ix = dd(cam.r * (2.0 * cam.aspect * cam.s / cam.width as f32)) * cone_scale;
        let iy = dd(cam.u * (-2.0 * cam.s / cam.height as f32)) * cone_scale;
        let mut c = Cone::new(cam.eye, dir, &[]);
        let incr = c.fp_of(ix, iy);
        c.add_pair(Fp::ZERO, incr);
        if cam.aperture > 0.0 {
            // Lens: `lens_scale` × radius `aperture` at t = 0, zero at the focal plane.
            let t_focus = cam.focal_dist / dir.dot(cam.f).max(1e-3);
            let a = cam.aperture * lens_scale;
            let s = c.fp_of(cam.r * a, cam.u * a);
            c.add_pair(s, s.scale(-1.0 / t_focus));
        }
        c
    }

    /// The cone in an instance's object space (`inv` maps world to object). Object-space t
    /// is `scale`·(world t); the footprint is carried over by the linear part, projected onto
    /// the new frame (exact for similarity transforms).
    pub fn to_object(&self, inv: &Affine3A) -> (Cone, f32) {
        let l = Mat3::from(inv.matrix3);
        let d = l * self.dir;
        let sc = d.length();
        let dir = d / sc;
        let org = inv.transform_point3(self.org);
        let (u, v) = onb(dir);
        let lu = l * self.u;
        let lv = l * self.v;
        let t0 = Vec2::new(lu.dot(u), lv.dot(u));
        let t1 = Vec2::new(lu.dot(v), lv.dot(v));
        let a = congruence(self.a, t0, t1);
        let b = congruence(self.b, t0, t1);
        let c = congruence(self.c, t0, t1);
        let inv_s = 1.0 / sc;
        (
            Cone {
                org,
                dir,
                u,
                v,
                a,
                b: b.scale(inv_s),
                c: c.scale(inv_s * inv_s),
                tmin: self.tmin * sc,
                tmax: if self.tmax.is_finite() { self.tmax * sc } else { f32::INFINITY },
            },
            sc,
        )
    }
}

/// Projects a footprint vector `f` (perpendicular to `dir`) along `dir` onto the plane with
/// unit normal `n`; the stretch is limited to 20× (grazing incidence).
#[inline]
pub fn project_on_plane(f: Vec3, dir: Vec3, n: Vec3) -> Vec3 {
    let dn = dir.dot(n);
    let dn = if dn.abs() < 0.05 { 0.05f32.copysign(dn) } else { dn };
    f - dir * (f.dot(n) / dn)
}

#[inline]
pub fn reflect(d: Vec3, n: Vec3) -> Vec3 {
    d - n * (2.0 * d.dot(n))
}

/// Refraction of unit `d` at unit `n` (facing against d) with η = n₁/n₂; None on total
/// internal reflection.
#[inline]
pub fn refract(d: Vec3, n: Vec3, eta: f32) -> Option<Vec3> {
    let cos_i = -d.dot(n);
    let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
    if k < 0.0 {
        None
    } else {
        Some((d * eta + n * (eta * cos_i - k.sqrt())).normalize())
    }
}

/// What leaves a surface.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outgoing {
    Reflect,
    /// Refraction with η = n₁/n₂.
    Refract(f32),
}

/// The reflected or refracted cone at surface point `p` with unit normal `n` (facing the
/// incoming ray), shape operator `w` (n(p+δ) ≈ normalize(n + w·δ), from ∇n), for an incoming
/// cone with direction `dir` whose footprint at the hit is `fs = [f0, f1, d0, d1, x0, x1]`
/// (world semi-axes, the direction differentials of the rays through them, and the spread
/// of the rays through the centre, see [`Cone::footprint_and_spread`]). Both parts are
/// carried over as the paper carries one cone: the footprint's pair to (startDev, incrDev),
/// the centre rays' spread to a second pair with zero startDev (their bent directions);
/// their squares add. `rough_spread` is a blurry reflection's radial spread per unit
/// distance (§6: tan(roughness), times the tracer's `rough_scale`), added as a third pair.
/// Returns None on total internal reflection of the centre ray (the caller reflects instead).
pub fn secondary(p: Vec3, dir: Vec3, n: Vec3, w: &Mat3, fs: [Vec3; 6], out: Outgoing, rough_spread: f32) -> Option<Cone> {
    let bend = |d: Vec3, nn: Vec3| -> Option<Vec3> {
        match out {
            Outgoing::Reflect => Some(reflect(d, nn)),
            Outgoing::Refract(eta) => refract(d, nn, eta),
        }
    };
    let r = bend(dir, n)?;
    // The rays through the axis ends: a refracted one that is totally reflected (only the
    // centre ray decides, §4.2) leaves along the surface, the limit of its side's fan.
    let bend_edge = |d: Vec3, nn: Vec3| -> Option<Vec3> {
        match out {
            Outgoing::Reflect => Some(reflect(d, nn)),
            Outgoing::Refract(eta) => refract(d, nn, eta).or_else(|| (d - nn * d.dot(nn)).try_normalize()),
        }
    };
    let g0 = project_on_plane(fs[0], dir, n);
    let g1 = project_on_plane(fs[1], dir, n);
    let mut c = Cone::new(p, r, &[]);
    let start = c.fp_of(g0, g1);
    // The ray through p + g arrives with direction dir + dd and meets the normal there.
    let dir_at = |g: Vec3, dd: Vec3| -> Vec3 {
        let nn = (n + *w * g).normalize_or_zero();
        let di = (dir + dd).normalize_or_zero();
        if nn == Vec3::ZERO || di == Vec3::ZERO || !nn.is_finite() || !di.is_finite() {
            return r;
        }
        bend_edge(di, nn).unwrap_or(r)
    };
    let o0 = dir_at(g0, fs[2]) - r;
    let o1 = dir_at(g1, fs[3]) - r;
    let incr = c.fp_of(o0 - r * r.dot(o0), o1 - r * r.dot(o1));
    c.add_pair(start, incr);
    if fs[4] != Vec3::ZERO || fs[5] != Vec3::ZERO {
        let x0 = dir_at(Vec3::ZERO, fs[4]) - r;
        let x1 = dir_at(Vec3::ZERO, fs[5]) - r;
        c.add_pair(Fp::ZERO, c.fp_of(x0 - r * r.dot(x0), x1 - r * r.dot(x1)));
    }
    if rough_spread > 0.0 {
        c.add_pair(Fp::ZERO, Fp::diag(rough_spread));
    }
    Some(c)
}

/// A blurry reflection's radial spread per unit distance (§6, "Special Effects"): tan of
/// the roughness angle (clamped below 80°) × `scale` (`--rough-scale`, see the module notes).
pub fn rough_spread(roughness: f32, scale: f32) -> f32 {
    if roughness > 0.0 {
        roughness.min(1.4).tan() * scale
    } else {
        0.0
    }
}

/// An elliptical light's axes as the shadow cone's Gaussian sees them: × `scale`
/// (`--light-scale`, see the module notes).
pub fn light_axes(axis_a: Vec3, axis_b: Vec3, scale: f32) -> (Vec3, Vec3) {
    (axis_a * scale, axis_b * scale)
}

/// The shadow cone from surface point `p` towards a light at `light_pos` (distance `dist`):
/// the surface footprint `(g0, g1)` shrinking to zero at the light, plus the light ellipse
/// `(axis_a, axis_b)` (zero for a point light) growing from zero at the surface.
///
/// `(g0, g1)` is the footprint *on the surface* (§4.2: "projecting the incoming ray footprint
/// onto the tangent plane", along the incoming ray: [`project_on_plane`] with the incoming
/// direction), which the shadow cone sees across its own direction ("transformed into ray
/// coordinates", [`Cone::fp_of`]). Until stop 31 the caller passed the incoming cone's axes
/// and this function projected them along the *light* direction, which shrank a grazing
/// view's footprint on the floor instead of stretching it (review finding; BENCHMARKS.md, stop 31).
pub fn shadow(p: Vec3, g0: Vec3, g1: Vec3, light_pos: Vec3, axis_a: Vec3, axis_b: Vec3) -> (Cone, f32) {
    let to = light_pos - p;
    let dist = to.length();
    let dir = to / dist;
    let mut c = Cone::new(p, dir, &[]);
    let s = c.fp_of(g0, g1);
    c.add_pair(s, s.scale(-1.0 / dist));
    if axis_a != Vec3::ZERO || axis_b != Vec3::ZERO {
        let l = c.fp_of(axis_a - dir * dir.dot(axis_a), axis_b - dir * dir.dot(axis_b));
        c.add_pair(Fp::ZERO, l.scale(1.0 / dist));
    }
    (c, dist)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::Camera;

    /// Test of the issue: a primary cone's footprint equals the pixel size at distance t.
    #[test]
    fn primary_footprint_is_the_pixel() {
        let cam = Camera { eye: Vec3::ZERO, look: Vec3::new(0.0, 0.0, -1.0), up: Vec3::Y, fovy: 60.0, ..Default::default() };
        let fr = cam.frame(200, 100);
        for (i, j) in [(100, 50), (0, 0), (199, 99), (37, 80)] {
            let c = Cone::primary(&fr, i, j, 1.0, 1.0);
            for t in [0.5f32, 3.0, 40.0] {
                // Pixel neighbours' directions at distance t, projected on the plane ⟂ dir.
                let d0 = fr.pixel_center_dir(i, j);
                let p0 = d0 * t;
                let px = fr.dir_at(i as f32 + 1.5, j as f32 + 0.5);
                let py = fr.dir_at(i as f32 + 0.5, j as f32 + 1.5);
                // Point on the neighbour ray at the same distance along d0.
                let qx = px * (t / px.dot(d0));
                let qy = py * (t / py.dot(d0));
                // The ellipse spanned by the two pixel steps (they are skewed off-axis).
                let fp = c.fp_of(qx - p0, qy - p0);
                let want = eigen_1(sq(fp), 1e-9, 1e-30);
                let e = eigen_1(c.sigma(t), 1e-9, 1e-30);
                let (mx, mn) = (want.s1, want.s2);
                assert!((e.s1 - mx).abs() < 0.03 * mx, "major {} vs pixel {mx} at ({i},{j}) t={t}", e.s1);
                assert!((e.s2 - mn).abs() < 0.03 * mn, "minor {} vs pixel {mn}", e.s2);
            }
            assert!((c.dir - fr.pixel_center_dir(i, j)).length() < 1e-5);
        }
    }

    /// [`Cone::sigma_x8`] against its scalar reference [`Cone::sigma`], lane by lane, bit for
    /// bit: both evaluate a + t·(b + t·c) with the same IEEE multiplications and additions in
    /// the same order, and neither Rust nor `wide` contracts them to FMA (not even with
    /// `target-cpu=x86-64-v3`), so the tolerance is zero (NaN lanes: NaN in both). Random
    /// cones (one to three pairs) and degenerate ones: zero footprint, rank 1 (colinear
    /// columns), near-singular, huge (Σ overflowing to ∞), tiny (subnormal), and NaN or ∞ in
    /// the footprint; depths random, negative, zero, huge, ±∞ and NaN.
    #[test]
    fn sigma_x8_matches_scalar_bit_for_bit() {
        let mut s = crate::core::rng::Sampler::new(5, 0, 0);
        let mut r = |lo: f32, hi: f32| lo + (hi - lo) * s.next();
        let mut cones = vec![];
        for i in 0..400 {
            let k = 10f32.powf(r(-6.0, 3.0));
            let mut fp = || Fp { c0: Vec2::new(r(-1.0, 1.0), r(-1.0, 1.0)) * k, c1: Vec2::new(r(-1.0, 1.0), r(-1.0, 1.0)) * k };
            let pairs: Vec<(Fp, Fp)> = (0..1 + i % 3).map(|_| (fp(), fp())).collect();
            cones.push(Cone::new(Vec3::ZERO, Vec3::new(0.3, -0.5, 0.8).normalize(), &pairs));
        }
        let col = |a: Vec2, k: f32| Fp { c0: a, c1: a * k };
        let degenerate: Vec<Vec<(Fp, Fp)>> = vec![
            vec![],                                                                                 // zero footprint
            vec![(Fp::ZERO, Fp::ZERO)],                                                             // zero pairs
            vec![(Fp::ZERO, col(Vec2::new(0.3, -0.7), 2.0))],                                       // rank 1 (colinear columns)
            vec![(col(Vec2::new(1.0, 2.0), -0.5), col(Vec2::new(1.0, 2.0), 3.0))],                  // rank 1 both
            vec![(Fp { c0: Vec2::new(1.0, 2.0), c1: Vec2::new(2.0, 4.0 + 1e-6) }, Fp::diag(1e-7))], // near-singular
            vec![(Fp::diag(1e19), Fp::diag(1e19))],                                                 // squares overflow to ∞
            vec![(Fp::diag(3e38), Fp::diag(-3e38))],
            vec![(Fp::diag(1e-23), Fp::diag(1e-22))], // subnormal squares
            vec![(Fp::diag(f32::NAN), Fp::ZERO)],
            vec![(Fp::ZERO, Fp { c0: Vec2::new(f32::NAN, 1.0), c1: Vec2::ZERO })],
            vec![(Fp::diag(f32::INFINITY), Fp::diag(1.0))],
            vec![(Fp::diag(1.0), Fp::diag(f32::NEG_INFINITY))],
        ];
        for pairs in &degenerate {
            cones.push(Cone::new(Vec3::ZERO, Vec3::Z, pairs));
        }
        // Σ set directly: an indefinite one and mixed signs (not reachable from pairs, but
        // `sigma_x8` must not care).
        let mut odd = Cone::new(Vec3::ZERO, Vec3::Z, &[]);
        (odd.a, odd.b, odd.c) =
            (Sym2 { a: -1.0, b: 2.0, c: 0.5 }, Sym2 { a: 1e-30, b: -0.0, c: f32::MAX }, Sym2 { a: -3.0, b: 0.0, c: 1e30 });
        cones.push(odd);
        let special = [0.0, -0.0, -1.0, 1e-30, 1e10, 1e20, f32::MAX, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, 3.5, -1e20];
        let same = |x: f32, y: f32| x.to_bits() == y.to_bits() || (x.is_nan() && y.is_nan());
        let mut nan_lanes = 0;
        for (ci, cone) in cones.iter().enumerate() {
            for rep in 0..4 {
                let t: [f32; 8] = std::array::from_fn(|l| match (rep, l) {
                    (0, _) => special[l],
                    (1, _) => special[l + 4],
                    _ => 10f32.powf(r(-4.0, 4.0)) * if l % 3 == 0 { -1.0 } else { 1.0 },
                });
                let (a, b, c) = cone.sigma_x8(wide::f32x8::from(t));
                let (a, b, c) = (a.to_array(), b.to_array(), c.to_array());
                for l in 0..8 {
                    let want = cone.sigma(t[l]);
                    assert!(
                        same(a[l], want.a) && same(b[l], want.b) && same(c[l], want.c),
                        "cone {ci} lane {l}, t = {}: x8 ({}, {}, {}) vs scalar {want:?}",
                        t[l],
                        a[l],
                        b[l],
                        c[l]
                    );
                    nan_lanes += want.a.is_nan() as u32;
                }
            }
        }
        assert!(nan_lanes > 0, "the NaN cases were not reached");
    }

    #[test]
    fn depth_of_field_cone_is_narrowest_at_focus() {
        let cam = Camera { eye: Vec3::ZERO, look: Vec3::new(0.0, 0.0, -1.0), up: Vec3::Y, fovy: 40.0, aperture: 0.1, focal_dist: 5.0 };
        let fr = cam.frame(64, 64);
        let c = Cone::primary(&fr, 32, 32, 1.0, 1.0);
        let size = |t: f32| eigen_1(c.sigma(t), 1e-9, 1e-30).s1;
        let pixel_only = Cone::primary(&Camera { aperture: 0.0, ..cam.clone() }.frame(64, 64), 32, 32, 1.0, 1.0);
        assert!(size(5.0) < size(2.0) && size(5.0) < size(9.0));
        // At focus only the pixel cone remains.
        assert!((size(5.0) - eigen_1(pixel_only.sigma(5.0), 1e-9, 1e-30).s1).abs() < 1e-3);
        assert!((size(0.0) - 0.1).abs() < 1e-3);
    }

    #[test]
    fn mirror_plane_keeps_the_spread_and_sphere_widens_it() {
        // A cone hits a flat mirror head-on: the reflected cone continues with the same
        // growth rate (as if it went on through the mirror image).
        let dir = Vec3::new(0.0, 0.0, -1.0);
        let n = Vec3::Z;
        let incoming = Cone::new(Vec3::new(0.0, 0.0, 10.0), dir, &[(Fp::ZERO, Fp::diag(0.01))]);
        let fs = incoming.footprint_and_spread(10.0, 1e-9, 1e-30);
        let flat = secondary(Vec3::ZERO, dir, n, &Mat3::ZERO, fs, Outgoing::Reflect, 0.0).unwrap();
        assert!((flat.dir - Vec3::Z).length() < 1e-6);
        let s = |c: &Cone, t: f32| eigen_1(c.sigma(t), 1e-9, 1e-30).s1;
        assert!((s(&flat, 5.0) - s(&incoming, 15.0)).abs() < 1e-4, "{} vs {}", s(&flat, 5.0), s(&incoming, 15.0));
        // Convex mirror (unit sphere: w = I on the tangent plane) spreads it more.
        let w = Mat3::from_diagonal(Vec3::new(1.0, 1.0, 0.0));
        let convex = secondary(Vec3::ZERO, dir, n, &w, fs, Outgoing::Reflect, 0.0).unwrap();
        assert!(s(&convex, 5.0) > 2.0 * s(&flat, 5.0));
        // Roughness widens it further.
        let rough = secondary(Vec3::ZERO, dir, n, &Mat3::ZERO, fs, Outgoing::Reflect, 0.1).unwrap();
        let want = (s(&flat, 5.0).powi(2) + (5.0f32 * 0.1).powi(2)).sqrt();
        assert!((s(&rough, 5.0) - want).abs() < 1e-3, "roughness adds in quadrature");
    }

    /// The minor axis of a clamped footprint grows at the cone's own rate, not at a rate
    /// diluted by the clamp's inflation (stop 32), and never faster than the cone's t² term.
    #[test]
    fn clamped_minor_axis_keeps_its_growth_rate() {
        let dir = Vec3::new(0.0, 0.0, -1.0);
        let c = Cone::new(Vec3::new(0.0, 0.0, 10.0), dir, &[(Fp::ZERO, Fp { c0: Vec2::new(0.01, 0.0), c1: Vec2::new(0.0, 1e-4) })]);
        for clamp in [1e-9, 1.0 / 16.0, 0.25] {
            let [f0, f1, d0, d1, ..] = c.footprint_and_spread(10.0, clamp, 1e-30);
            assert!((f0.length() - 0.1).abs() < 1e-5, "{f0}");
            assert!((f1.length() - (1e-3f32).max(clamp * 0.1)).abs() < 1e-6, "{f1}");
            assert!((d0.length() - 0.01).abs() < 1e-6, "{d0}");
            assert!((d1.length() - 1e-4).abs() < 1e-7, "clamp {clamp}: minor-axis rate {}", d1.length());
        }
        // A pair whose footprint passes through zero (a lens pair at its focus): the rate is
        // the bound, finite, where s vanishes.
        let lens = Cone::new(Vec3::ZERO, dir, &[(Fp::diag(0.1), Fp::diag(-0.02))]);
        let [_, _, d0, d1, ..] = lens.footprint_and_spread(5.0, 1.0 / 16.0, 1e-30);
        assert!(d0.is_finite() && d1.is_finite() && d0.length() <= 0.02 + 1e-6 && d1.length() <= 0.02 + 1e-6, "{d0} {d1}");
    }

    #[test]
    fn total_internal_reflection_by_centre_ray() {
        let dir = Vec3::new(1.0, -0.2, 0.0).normalize();
        let n = Vec3::Y;
        let fs = [Vec3::X * 0.01, Vec3::Z * 0.01, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, Vec3::ZERO];
        assert!(secondary(Vec3::ZERO, dir, n, &Mat3::ZERO, fs, Outgoing::Refract(1.5), 0.0).is_none());
        assert!(secondary(Vec3::ZERO, dir, n, &Mat3::ZERO, fs, Outgoing::Refract(1.0 / 1.5), 0.0).is_some());
    }

    #[test]
    fn object_space_cone_has_the_same_footprint() {
        let c = Cone::new(Vec3::new(1.0, 2.0, 3.0), Vec3::new(0.3, -0.4, 0.5).normalize(), &[(Fp::diag(0.02), Fp::diag(0.01))]);
        let xf = Affine3A::from_scale_rotation_translation(Vec3::splat(2.0), glam::Quat::from_rotation_y(0.7), Vec3::new(5.0, 0.0, 1.0));
        let inv = xf.inverse();
        let (o, sc) = c.to_object(&inv);
        assert!((sc - 0.5).abs() < 1e-5);
        let t = 7.0;
        let w = eigen_1(c.sigma(t), 1e-9, 1e-30);
        let ob = eigen_1(o.sigma(t * sc), 1e-9, 1e-30);
        assert!((ob.s1 - w.s1 * 0.5).abs() < 1e-4 && (ob.s2 - w.s2 * 0.5).abs() < 1e-4);
    }

    #[test]
    fn shadow_cone_ends_at_the_light_ellipse() {
        let (c, d) = shadow(Vec3::ZERO, Vec3::X * 0.05, Vec3::Z * 0.05, Vec3::new(0.0, 4.0, 0.0), Vec3::X, Vec3::Z * 0.5);
        assert!((d - 4.0).abs() < 1e-6);
        let e = eigen_1(c.sigma(4.0), 1e-9, 1e-30);
        assert!((e.s1 - 1.0).abs() < 1e-4 && (e.s2 - 0.5).abs() < 1e-4);
        let e0 = eigen_1(c.sigma(0.0), 1e-9, 1e-30);
        assert!((e0.s1 - 0.05).abs() < 1e-4);
    }

    /// §4.2: a shadow cone starts with the incoming footprint projected onto the tangent
    /// plane along the *incoming* ray, seen across the light direction. A grazing view of a
    /// floor stretches the footprint along the view (here 10×), and a light straight above
    /// sees all of that stretch; a light low along the view sees it foreshortened.
    #[test]
    fn shadow_cone_starts_with_the_surface_footprint() {
        let n = Vec3::Y;
        let dir_in = Vec3::new(1.0, -0.1, 0.0).normalize();
        let f0 = Vec3::new(0.1, 1.0, 0.0).normalize() * 0.01; // ⟂ dir_in, in the view's vertical
        let f1 = Vec3::Z * 0.01;
        let (g0, g1) = (project_on_plane(f0, dir_in, n), project_on_plane(f1, dir_in, n));
        assert!(g0.dot(n).abs() < 1e-7 && (g0.length() - 0.1005).abs() < 1e-3, "{g0}");
        let start = |light: Vec3| {
            let (c, _) = shadow(Vec3::ZERO, g0, g1, light, Vec3::ZERO, Vec3::ZERO);
            eigen_1(c.sigma(0.0), 1e-12, 1e-30)
        };
        let above = start(Vec3::new(0.0, 5.0, 0.0));
        assert!((above.s1 - g0.length()).abs() < 1e-4 && (above.s2 - 0.01).abs() < 1e-5, "{above:?}");
        let el: f32 = 0.5; // light 0.5 rad above the floor, in the view's plane
        let low = start(Vec3::new(el.cos(), el.sin(), 0.0) * 5.0);
        assert!((low.s1 - g0.length() * el.sin()).abs() < 1e-4, "{low:?}");
    }
}
