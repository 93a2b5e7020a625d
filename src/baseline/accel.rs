//! The one intersection interface of the conventional tracers, implemented by Embree
//! (`--accel embree`) and by obvhs' CWBVH (`--accel bvh`): single rays and packets of
//! K = 8, closest hit and occlusion, over two-level instancing (see `scene` docs).

use crate::core::stats::Counters;
use crate::error::Result;
use crate::scene::Scene;
use glam::Vec3;

/// Packet width used across the tracers (DESIGN.md: `K` rays per packet).
pub const K: usize = 8;

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ray {
    pub org: Vec3,
    /// Need not be unit length; `t` is measured in multiples of it.
    pub dir: Vec3,
    pub tnear: f32,
    pub tfar: f32,
}

impl Ray {
    pub fn new(org: Vec3, dir: Vec3) -> Self {
        Ray { org, dir, tnear: 0.0, tfar: f32::INFINITY }
    }
    pub fn segment(org: Vec3, dir: Vec3, tnear: f32, tfar: f32) -> Self {
        Ray { org, dir, tnear, tfar }
    }
    /// Rays with NaN/inf origins or directions, zero directions, or an empty interval never
    /// hit (both back-ends treat them as misses instead of passing them to the kernels).
    #[inline]
    pub fn is_valid(&self) -> bool {
        self.org.is_finite()
            && self.dir.is_finite()
            && self.dir != Vec3::ZERO
            && !self.tnear.is_nan()
            && !self.tfar.is_nan()
            && self.tnear <= self.tfar
    }
}

/// A closest hit: distance, barycentrics (u for v1, v for v2, as in Embree), triangle index
/// in its mesh, and leaf-instance index (see [`crate::scene::Scene::leaf_instances`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    pub t: f32,
    pub u: f32,
    pub v: f32,
    pub prim: u32,
    pub inst: u32,
}

/// Which methods take which [`AccelKind`] (one wording for `render`'s and `bench`'s errors).
pub const ACCEL_USE: &str = "whitted and distributed: embree, bvh, octree; lod: embree, bvh";

/// Which back-end to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AccelKind {
    Embree,
    Bvh,
    Octree,
}

impl AccelKind {
    pub fn name(self) -> &'static str {
        match self {
            AccelKind::Embree => "embree",
            AccelKind::Bvh => "bvh",
            AccelKind::Octree => "octree",
        }
    }
}

pub trait Accel: Sync + Send {
    fn name(&self) -> &'static str;
    /// Closest hit along `ray` within [tnear, tfar].
    fn intersect1(&self, ray: &Ray, c: &mut Counters) -> Option<Hit>;
    /// Whether anything lies within [tnear, tfar].
    fn occluded1(&self, ray: &Ray, c: &mut Counters) -> bool;
    /// K rays at once; lanes whose bit in `valid` is clear are left untouched.
    fn intersect8(&self, rays: &[Ray; K], valid: u8, out: &mut [Option<Hit>; K], c: &mut Counters) {
        for i in 0..K {
            if valid & (1 << i) != 0 {
                out[i] = self.intersect1(&rays[i], c);
            }
        }
    }
    fn occluded8(&self, rays: &[Ray; K], valid: u8, out: &mut [bool; K], c: &mut Counters) {
        for i in 0..K {
            if valid & (1 << i) != 0 {
                out[i] = self.occluded1(&rays[i], c);
            }
        }
    }
    /// Bytes held by the acceleration structure (not counting the scene's meshes).
    fn memory_bytes(&self) -> usize;
    /// Closest hit among the leaf instances `filter` admits (used by the per-ray LOD tracer's
    /// enter/exit list). The default steps past rejected hits with repeated queries (at most
    /// 64), so it loses an admitted hit at exactly the distance of a rejected one (coplanar
    /// faces of touching objects); back-ends that can test the filter during traversal
    /// override it (the BVH per instance, Embree in a context filter function).
    fn intersect1_filtered(&self, ray: &Ray, filter: InstFilter, c: &mut Counters) -> Option<Hit> {
        let mut r = *ray;
        for _ in 0..64 {
            match self.intersect1(&r, c) {
                Some(h) if !filter.admits(h.inst) => {
                    r.tnear = next_up(h.t);
                    if !(r.tnear <= r.tfar) {
                        return None;
                    }
                }
                h => return h,
            }
        }
        None
    }
}

/// Which leaf instances a filtered query may hit.
#[derive(Clone, Copy, Debug)]
pub enum InstFilter<'a> {
    All,
    /// Every instance but these.
    Skip(&'a [u32]),
    /// This instance only.
    Only(u32),
}

impl InstFilter<'_> {
    #[inline(always)]
    pub fn admits(&self, inst: u32) -> bool {
        match self {
            InstFilter::All => true,
            InstFilter::Skip(s) => !s.contains(&inst),
            InstFilter::Only(o) => *o == inst,
        }
    }
}

/// The next representable float above `t` (to step past a hit).
#[inline]
pub fn next_up(t: f32) -> f32 {
    if t.is_nan() || t == f32::INFINITY {
        return t;
    }
    if t == 0.0 {
        return f32::from_bits(1);
    }
    let b = t.to_bits();
    f32::from_bits(if t > 0.0 { b + 1 } else { b - 1 })
}

/// Builds the requested back-end for a validated scene (the octree with the paper's defaults).
pub fn build<'a>(kind: AccelKind, scene: &'a Scene) -> Result<Box<dyn Accel + 'a>> {
    build_with(kind, scene, &crate::multires::build::BuildParams::default())
}

/// [`build`], with the octree's build parameters (`--k`, `--oversampling`, `--point-weights`),
/// so that `--method whitted --accel octree` runs on the same octree as `--method multires`
/// with the same options.
pub fn build_with<'a>(kind: AccelKind, scene: &'a Scene, octree: &crate::multires::build::BuildParams) -> Result<Box<dyn Accel + 'a>> {
    match kind {
        AccelKind::Bvh => Ok(Box::new(super::bvh::BvhAccel::build(scene)?)),
        #[cfg(feature = "embree")]
        AccelKind::Embree => Ok(Box::new(super::embree::EmbreeAccel::build(scene)?)),
        #[cfg(not(feature = "embree"))]
        AccelKind::Embree => {
            Err(crate::error::Error::Usage("this build has no Embree (cargo feature 'embree' is off); use --accel bvh".into()))
        }
        AccelKind::Octree => Ok(Box::new(crate::multires::octree_accel::OctreeAccel::build(scene, octree)?)),
    }
}
