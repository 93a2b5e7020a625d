//! Surface interaction and the conventional shading model shared by the Whitted and the
//! distributed tracer (Wand & Straßer §6: "a conventional raytracer based on the same code
//! basis"): Phong local illumination with shadow rays, mirror reflection, refraction with the
//! total-internal-reflection fallback, a recursion depth limit.
//!
//! Radiometry: lights are given as radiant intensity I; a diffuse surface of albedo ρ
//! (`color·kd`) lit at distance d and incidence θ has radiance ρ/π · I·cosθ/d². The Phong
//! highlight is energy-normalised: ks·(n+2)/(2π)·cosⁿα · I·cosθ/d².
//!
//! With a sampler (distributed ray tracing, Cook et al. 1984) the elliptical lights are
//! sampled uniformly over their area and glossy reflections are sampled uniformly in a cone
//! of half-angle `roughness` around the mirror direction; without one (Whitted) lights are
//! taken at their centre and reflections are perfect mirrors.

use super::accel::{Accel, Hit, Ray};
use crate::core::rng::Sampler;
use crate::core::stats::{Counter, Counters};
use crate::scene::{LeafInstance, Light, Material, Scene};
use glam::Vec3;

/// Everything an integrator needs, shared read-only by all threads.
pub struct TraceCtx<'a> {
    pub scene: &'a Scene,
    pub leaves: &'a [LeafInstance],
    pub accel: &'a dyn Accel,
    pub max_depth: u32,
}

/// A resolved hit: world position, unit geometric and shading normals facing the incoming
/// ray, whether the ray came from the front (outside), and the material.
pub struct Surface<'a> {
    pub p: Vec3,
    /// Offset of secondary-ray origins from `p` ([`SURFACE_EPS_REL`] of the hit triangle's
    /// world-space coordinates' magnitude): above `p`'s rounding, at any scale.
    pub eps: f32,
    pub ng: Vec3,
    pub ns: Vec3,
    pub front: bool,
    pub mat: &'a Material,
}

impl<'a> TraceCtx<'a> {
    pub fn surface(&self, ray: &Ray, hit: &Hit) -> Surface<'a> {
        let leaf = &self.leaves[hit.inst as usize];
        let mesh = &self.scene.meshes[leaf.mesh as usize];
        let [i0, i1, i2] = mesh.tris[hit.prim as usize];
        let (p0, p1, p2) = (mesh.pos(i0), mesh.pos(i1), mesh.pos(i2));
        let ng_obj = (p1 - p0).cross(p2 - p0);
        let w = 1.0 - hit.u - hit.v;
        let ns_obj = mesh.normal(i0) * w + mesh.normal(i1) * hit.u + mesh.normal(i2) * hit.v;
        let nm = glam::Mat3::from(leaf.normal_mat);
        let mut ng = (nm * ng_obj).normalize_or_zero();
        let mut ns = (nm * ns_obj).normalize_or_zero();
        if ns == Vec3::ZERO {
            ns = ng;
        }
        // The hit point from the barycentrics on the triangle, not ray.org + t·dir: that one
        // carries the rounding of the camera's distance, and 1,700 × (1 + |p|) away the
        // shadow and reflected rays hit their own surface (speckles; precision review, stop
        // 77). The offset follows the magnitude of the triangle's coordinates, which bounds
        // this p's rounding, instead of 1e-4·(1 + |p|), whose absolute 1e-4 swallowed scenes
        // scaled by 1e-4 and whose relative 1e-4 swallowed scenes moved 1e4 from the origin.
        let world = [p0, p1, p2].map(|q| leaf.xform.transform_point3(q));
        let p = world[0] * w + world[1] * hit.u + world[2] * hit.v;
        let mag = world.iter().fold(p.abs(), |m, q| m.max(q.abs())).max_element();
        let eps = (SURFACE_EPS_REL * mag).max(f32::MIN_POSITIVE);
        let front = ng.dot(ray.dir) < 0.0;
        if !front {
            ng = -ng;
        }
        if ns.dot(ng) < 0.0 {
            ns = -ns;
        }
        let mat_id = leaf.material.unwrap_or(mesh.mat[hit.prim as usize]);
        Surface { p, eps, ng, ns, front, mat: &self.scene.materials[mat_id as usize] }
    }

    /// Radiance arriving along `ray` (unit direction). `depth` counts bounces so far.
    pub fn radiance(&self, ray: &Ray, depth: u32, smp: Option<&mut Sampler>, c: &mut Counters) -> Vec3 {
        let Some(hit) = self.accel.intersect1(ray, c) else {
            return self.scene.background;
        };
        self.shade(ray, &hit, depth, smp, c)
    }

    /// Shades a known hit (used directly for packet-traced primary rays).
    pub fn shade(&self, ray: &Ray, hit: &Hit, depth: u32, mut smp: Option<&mut Sampler>, c: &mut Counters) -> Vec3 {
        let s = self.surface(ray, hit);
        let v = -ray.dir;
        let eps = s.eps;
        let p_out = s.p + s.ng * eps;
        let mut l = self.direct(&s, v, p_out, smp.as_deref_mut(), c, |r, c| self.accel.occluded1(r, c));
        if depth >= self.max_depth {
            return l;
        }
        let sec = secondary(&s, v);
        if let Some(t) = sec.refract {
            c.inc(Counter::rays_refract);
            let lt = self.radiance(&Ray::new(s.p - s.ng * eps, t), depth + 1, smp.as_deref_mut(), c);
            l += lt * s.mat.color * s.mat.transmit;
        }
        if sec.reflect_w > 0.0 {
            let mut dir = sec.mirror;
            if s.mat.roughness > 0.0 {
                if let Some(r) = smp.as_deref_mut() {
                    dir = sample_cone(sec.mirror, s.mat.roughness, r.next(), r.next());
                    if dir.dot(s.ng) <= 0.0 {
                        dir = sec.mirror;
                    }
                }
            }
            c.inc(Counter::rays_reflect);
            l += self.radiance(&Ray::new(p_out, dir), depth + 1, smp, c) * sec.reflect_w;
        }
        l
    }

    /// Local illumination at a surface: ambient plus Phong from every light, each behind a
    /// shadow ray answered by `occluded` (so tracers with their own visibility, such as the
    /// per-ray LOD tracer, share the shading exactly). `p_out` is the hit point offset to the
    /// side of the incoming ray.
    pub fn direct(
        &self,
        s: &Surface,
        v: Vec3,
        p_out: Vec3,
        mut smp: Option<&mut Sampler>,
        c: &mut Counters,
        mut occluded: impl FnMut(&Ray, &mut Counters) -> bool,
    ) -> Vec3 {
        let m = s.mat;
        let mut l = self.scene.ambient * m.color * m.kd;
        for light in &self.scene.lights {
            let lp = match (&mut smp, light) {
                (Some(r), Light::Ellipse { .. }) => {
                    let (a, b) = r.next2();
                    light.sample(a, b)
                }
                _ => light.center(),
            };
            let to_l = lp - p_out;
            let d2 = to_l.length_squared();
            if !(d2 > 0.0) {
                continue;
            }
            let d = d2.sqrt();
            let ldir = to_l / d;
            let cos = s.ns.dot(ldir);
            if cos <= 0.0 || s.ng.dot(ldir) <= 0.0 {
                continue;
            }
            if self.scene.shadows {
                c.inc(Counter::rays_shadow);
            }
            if self.scene.shadows && occluded(&Ray::segment(p_out, ldir, 0.0, d * (1.0 - 1e-4)), c) {
                continue;
            }
            let e = light.intensity() * (cos / d2);
            let mut f = m.color * (m.kd / std::f32::consts::PI);
            if m.ks > 0.0 {
                let r = (2.0 * s.ns.dot(ldir)) * s.ns - ldir;
                let ca = r.dot(v).max(0.0);
                f += Vec3::splat(m.ks * (m.shininess + 2.0) / std::f32::consts::TAU * ca.powf(m.shininess));
            }
            l += f * e;
        }
        l
    }
}

/// Offset of secondary-ray origins from a hit point ([`Surface::eps`]), relative to the
/// magnitude of the hit triangle's world coordinates: 4e-6, about 67 f32 steps of that
/// magnitude, where the point's rounding is a few (stop 77; it was 1e-4·(1 + |p|)).
pub const SURFACE_EPS_REL: f32 = 4e-6;

/// The secondary rays of a hit (Whitted): the refracted direction, weighted by
/// `color · transmit` (`None` without transparency or on total internal reflection, whose
/// share then goes to the mirror), the mirror direction and the reflected weight.
pub struct Secondary {
    pub refract: Option<Vec3>,
    pub mirror: Vec3,
    pub reflect_w: f32,
}

pub fn secondary(s: &Surface, v: Vec3) -> Secondary {
    let m = s.mat;
    let cos_i = v.dot(s.ns).clamp(-1.0, 1.0);
    let mirror = (2.0 * cos_i) * s.ns - v;
    let mut reflect_w = m.reflect;
    let mut refract = None;
    if m.transmit > 0.0 {
        let eta = if s.front { 1.0 / m.ior } else { m.ior };
        let k = 1.0 - eta * eta * (1.0 - cos_i * cos_i);
        if k < 0.0 {
            // Total internal reflection: the transmitted part is reflected.
            reflect_w += m.transmit;
        } else {
            let t = (-v * eta + s.ns * (eta * cos_i - k.sqrt())).normalize();
            refract = Some(t);
        }
    }
    Secondary { refract, mirror, reflect_w }
}

/// Uniform direction in the cone of half-angle `theta_max` around unit `axis`.
pub fn sample_cone(axis: Vec3, theta_max: f32, u: f32, v: f32) -> Vec3 {
    let cos_max = theta_max.min(std::f32::consts::FRAC_PI_2).cos();
    let cos_t = 1.0 - u * (1.0 - cos_max);
    let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
    let phi = std::f32::consts::TAU * v;
    let (t, b) = crate::core::onb(axis);
    (t * (sin_t * phi.cos()) + b * (sin_t * phi.sin()) + axis * cos_t).normalize()
}

#[cfg(test)]
mod tests {
    use super::*;
    #[test]
    fn cone_samples_stay_in_cone() {
        let axis = Vec3::new(0.3, -0.5, 0.8).normalize();
        let mut s = Sampler::new(0, 0, 0);
        for _ in 0..1000 {
            let d = sample_cone(axis, 0.2, s.next(), s.next());
            assert!(d.dot(axis) >= 0.2f32.cos() - 1e-5);
            assert!((d.length() - 1.0).abs() < 1e-5);
        }
    }
}
