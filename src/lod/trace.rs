//! The two-pass per-ray LOD tracer (Papaioannou et al. §2.2, §3, §4), `--method lod`.
//!
//! Pass 1 traces the level-0 (primary) rays at full detail (or at the distance criterion's
//! model), shades them locally (Phong + shadow rays, exactly as the Whitted baseline), and
//! fills the *distortion buffer* with the reflected and refracted directions of each primary
//! hit. The disparities
//!
//! `d_r(i,j) = [acos(R(i,j)·R(i+1,j)) + acos(R(i,j)·R(i,j+1))] / 2π` (and `d_t` from T)
//!
//! give the level-1 LOD, `LOD⁽¹⁾ = LOD⁽⁰⁾·(1 − d)^f` (§3). Pass 2 traces the level-1 sub-trees.
//! Deeper rays carry the attenuation `k⁽ᵐ⁾ = k⁽ᵐ⁻¹⁾·k_r` (reflection) or `·k_t` (transmission)
//! and, when the disparity their level-1 ancestor measured exceeds `thres_LOD`, degrade by
//! `λ⁽ᵐ⁾ = 1 − a_LOD + a_LOD·k⁽ᵐ⁾`. Each ray keeps the list of objects it is inside with the
//! level it entered them at, and tests the exit against that level (Fig. 3). At levels ≥ 2,
//! of a reflected and a transmitted child whose strengths differ by more than 200 % only the
//! stronger is traced (§4, selective tracing), "provided that the LOD used is less than
//! 100 %": only when the incident ray's LOD selects a model coarser than L₀ (k > 0). A ray
//! whose LOD is below 1 but still maps to L₀ (a flat mirror's level-1 rays, whose absolute
//! disparity is the pixel's own angle; a chain of one level) uses the full-detail model and
//! keeps both children, so its sub-tree renders exactly as the full-detail tracer's. Shadow
//! rays use the level of the incident ray.
//!
//! Choices and deviations, written down:
//! - The λ formula in the paper's text reads `λ = 1` when `d > thres_LOD` and
//!   `1 − a + a·k` otherwise, while the sentences around it say the opposite ("the LOD for
//!   rays of level 2 or greater is only decreased when the ray disparity … is significant").
//!   The sentences are implemented: degradation only when `d > thres_LOD`.
//! - Our materials have no absorption `k_abs(l)`; the transmitted strength is
//!   `k_t = transmit · luminance(colour)` (the tint the Whitted shader applies), the
//!   reflected strength the mirror weight (including the total-internal-reflection share).
//! - A neighbour with no reflected (transmitted) ray — an opaque hit, a miss, total internal
//!   reflection — is replaced by the neighbour on the other side; with neither, that axis
//!   contributes no angle. Samples: with `--spp N` every sample index forms its own
//!   distortion buffer (the neighbours of sample s of a pixel are sample s of the adjacent
//!   pixels), so the disparity stays at pixel resolution as in the paper.
//! - The "enter/exit" list holds at most [`INSIDE_MAX`] objects (deeper nesting is not
//!   tracked). The exception test runs the query at the ray's level skipping the listed
//!   objects, then each listed object at its stored level, and keeps the nearest.
//! - `--lod-net-disparity` (off by default) subtracts the angle between the neighbouring
//!   *incident* rays from the outgoing angle, per axis: the disparity an object adds. The
//!   paper's absolute angles include the pixel's own angular size (about 0.0015 rad at 512²
//!   and 45°), which a flat mirror passes on unchanged; at that size it never lowers the
//!   level (LOD⁽¹⁾ > 0.99 maps to level 0), so both modes keep a flat mirror at full LOD.
//! - Parallelism: bands of 16 image rows in a rayon pool, each walked in 16×16 blocks; rayon's work stealing is the dynamic load
//!   balancing of §4 (an idle worker takes half of a busy worker's remaining range).

use super::chain::{level_of, LodScenes};
use crate::baseline::accel::{Accel, Hit, InstFilter, Ray};
use crate::baseline::render::{primary_row, Progress, RenderOpts, RenderOutput};
use crate::baseline::shade::{secondary, TraceCtx};
use crate::core::luminance;
use crate::core::rng::Sampler;
use crate::core::stats::{Counter, Counters};
use crate::error::{Error, Result};
use crate::film::Film;
use crate::scene::camera::CameraFrame;
use crate::scene::{LeafInstance, Material};
use glam::Vec3;
use rayon::prelude::*;
use std::time::Instant;

/// Objects a ray can be inside of at once (the enter/exit list of Fig. 3).
pub const INSIDE_MAX: usize = 4;

/// What lowers the level-1 LOD.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Selector {
    /// The paper's ray disparity between neighbouring pixels (§2.2).
    Disparity,
    /// Beyond the paper: the spread a ray cone gains at the surface, from its curvature.
    Cone,
}

/// When selective tracing (§4) may drop a child: "provided that the LOD used is less than
/// 100 %", read two ways.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum SelectiveOn {
    /// The model the ray's LOD selects is coarser than L₀ (the default since stop 50): a
    /// ray on the full-detail model renders its sub-tree as the full-detail tracer does.
    Model,
    /// The ray's LOD value is below 1 (the literal reading, used until stop 50): nearly
    /// every level-1 ray qualifies, since the absolute disparity is never exactly 0.
    Value,
}

/// The paper's parameters (§3, §4), each a named option.
#[derive(Clone, Debug)]
pub struct LodParams {
    /// Distortion factor f (paper: f > 1, typical 10–24).
    pub f: f32,
    /// Degradation rate a_LOD ∈ [0, 1] (paper: 0.4–0.6).
    pub a_lod: f32,
    /// Disparity threshold thres_LOD ∈ [0, 1] above which deeper rays degrade.
    pub thres: f32,
    /// Selective tracing (§4) on or off.
    pub selective: bool,
    /// Ray level from which selective tracing applies (paper: 2).
    pub selective_level: u32,
    /// Strength ratio above which the weaker child is dropped (paper: 200 % = 2).
    pub selective_ratio: f32,
    /// Which "LOD used" must be below 100 % for selective tracing ([`SelectiveOn`]).
    pub selective_on: SelectiveOn,
    /// Every ray uses this LOD (for tests and experiments): 1.0 = the full-detail tracer.
    pub force: Option<f32>,
    /// Disparity net of the incident rays' own divergence (a flat mirror then gives exactly
    /// zero); off = the paper's absolute angles.
    pub net_disparity: bool,
    pub selector: Selector,
}

impl Default for LodParams {
    fn default() -> Self {
        LodParams {
            f: 16.0,
            a_lod: 0.5,
            thres: 0.01,
            selective: true,
            selective_level: 2,
            selective_ratio: 2.0,
            selective_on: SelectiveOn::Model,
            force: None,
            net_disparity: false,
            selector: Selector::Disparity,
        }
    }
}

impl LodParams {
    pub fn validate(&self) -> Result<()> {
        if !(self.f.is_finite() && (1.0..=100.0).contains(&self.f)) {
            return Err(Error::Usage(format!("--lod-f {} out of range (1..=100; the paper uses 10-24)", self.f)));
        }
        if !(0.0..=1.0).contains(&self.a_lod) {
            return Err(Error::Usage(format!("--lod-a {} out of range (0..=1)", self.a_lod)));
        }
        if !(0.0..=1.0).contains(&self.thres) {
            return Err(Error::Usage(format!("--lod-threshold {} out of range (0..=1)", self.thres)));
        }
        if !(self.selective_ratio.is_finite() && self.selective_ratio >= 1.0) {
            return Err(Error::Usage(format!("--lod-selective-ratio {} must be >= 1", self.selective_ratio)));
        }
        if self.selective_level > 64 {
            return Err(Error::Usage(format!("--lod-selective-level {} is absurd", self.selective_level)));
        }
        if let Some(x) = self.force {
            if !(0.0..=1.0).contains(&x) {
                return Err(Error::Usage(format!("--lod-force {x} out of range (0..=1)")));
            }
        }
        // An option another one switches off is refused, as another method's options are
        // (`render::check_method_options`): until stop 80 `--no-selective` ignored the
        // selective-tracing options and `--lod-force` the LOD formula's f, a_LOD and
        // thres_LOD without a word (the same image either way).
        let d = Self::default();
        let ignored = |set: &[(bool, &str)], by: &str| match set.iter().find(|(s, _)| *s) {
            Some((_, o)) => Err(Error::Usage(format!("{o} has no effect beside {by}"))),
            None => Ok(()),
        };
        if !self.selective {
            ignored(
                &[
                    (self.selective_level != d.selective_level, "--lod-selective-level"),
                    (self.selective_ratio != d.selective_ratio, "--lod-selective-ratio"),
                    (self.selective_on != d.selective_on, "--lod-selective-on"),
                ],
                "--no-selective (selective tracing off)",
            )?;
        }
        if self.force.is_some() {
            ignored(
                &[(self.f != d.f, "--lod-f"), (self.a_lod != d.a_lod, "--lod-a"), (self.thres != d.thres, "--lod-threshold")],
                "--lod-force (every ray's LOD is given)",
            )?;
        }
        Ok(())
    }
}

/// The enter/exit list: (leaf instance, level it was entered at).
#[derive(Clone, Copy, Debug, Default)]
struct Inside {
    n: u8,
    e: [(u32, u8); INSIDE_MAX],
}

impl Inside {
    fn entries(&self) -> &[(u32, u8)] {
        &self.e[..self.n as usize]
    }
    fn enter(&mut self, inst: u32, level: u32) {
        if (self.n as usize) < INSIDE_MAX && !self.entries().iter().any(|e| e.0 == inst) {
            self.e[self.n as usize] = (inst, level as u8);
            self.n += 1;
        }
    }
    fn exit(&mut self, inst: u32) {
        if let Some(i) = self.entries().iter().position(|e| e.0 == inst) {
            self.e.copy_within(i + 1..self.n as usize, i);
            self.n -= 1;
        }
    }
}

/// What a ray carries besides its geometry.
#[derive(Clone, Copy, Debug)]
struct RayState {
    lod: f32,
    /// Attenuation k⁽ᵐ⁾.
    k: f32,
    /// Disparity measured for this ray's level-1 ancestor.
    d: f32,
    inside: Inside,
}

/// Per-pixel maps of pass 1 (averaged over the samples), for images and statistics.
#[derive(Clone, Debug, Default)]
pub struct LodMaps {
    pub width: u32,
    pub height: u32,
    pub d_r: Vec<f32>,
    pub d_t: Vec<f32>,
    /// LOD⁽¹⁾ of the reflected / transmitted level-1 ray (1 where there is none).
    pub lod_r: Vec<f32>,
    pub lod_t: Vec<f32>,
    /// The lowest LOD⁽¹⁾ of any level-1 ray of the pixel, over all samples (1 where there is
    /// none), not averaged: the pixel's coarsest level-1 model is `level_of` of it (stop 80:
    /// the averages above put a pixel with one sample at level 3 and three at 1 "at L₀").
    pub lod_min: Vec<f32>,
}

/// Everything a level-1 sub-tree needs from pass 1: the distortion buffer's directions and
/// what pass 2 would otherwise recompute from the primary hit's surface (stop 83: pass 2 ran
/// `TraceCtx::surface` and `secondary` a second time for every primary hit, about 1 % of a
/// full-detail frame's instructions). The values are the ones pass 1 computed, bit for bit,
/// so pass 2 spawns exactly the rays it spawned before.
#[derive(Clone, Copy)]
struct Cell<'a> {
    /// The primary ray's direction (the incident rays of `--lod-net-disparity`).
    dir: Vec3,
    /// Local shading of the primary hit (ambient, lights); the background on a miss.
    l0: Vec3,
    /// Reflected and transmitted directions (the distortion buffer), zero when absent.
    r: Vec3,
    t: Vec3,
    /// Origins of the reflected (`p + ng·eps`) and transmitted (`p − ng·eps`) rays.
    p_out: Vec3,
    p_in: Vec3,
    /// The reflected weight (mirror plus the total-internal-reflection share); > 0 exactly
    /// when `r` is set.
    kr: f32,
    /// The cone selector's (d_r, d_t) for this sample (zero with the disparity selector).
    cone: (f32, f32),
    /// The primary hit's material; `None`: no hit (or no secondary rays at `max_depth` 0).
    mat: Option<&'a Material>,
    /// The hit instance (entered by the transmitted ray when `front`).
    inst: u32,
    front: bool,
    /// A transmitted ray exists (`t` is then non-zero, a normalised direction).
    has_t: bool,
}

impl Cell<'_> {
    const EMPTY: Cell<'static> = Cell {
        dir: Vec3::Z,
        l0: Vec3::ZERO,
        r: Vec3::ZERO,
        t: Vec3::ZERO,
        p_out: Vec3::ZERO,
        p_in: Vec3::ZERO,
        kr: 0.0,
        cone: (0.0, 0.0),
        mat: None,
        inst: 0,
        front: false,
        has_t: false,
    };
}

pub struct LodTracer<'a> {
    /// Angle between neighbouring pixel-centre rays (radians), for the cone selector.
    pixel_angle: f32,
    ctxs: Vec<TraceCtx<'a>>,
    p: &'a LodParams,
    lvl_max: u32,
    max_depth: u32,
}

impl<'a> LodTracer<'a> {
    /// `accels[r]` intersects `ls.scenes[r]`; `leaves[r]` are its leaf instances.
    pub fn new(ls: &'a LodScenes, leaves: &'a [Vec<LeafInstance>], accels: &'a [Box<dyn Accel + 'a>], p: &'a LodParams) -> Self {
        let ctxs = ls
            .scenes
            .iter()
            .zip(leaves)
            .zip(accels)
            .map(|((s, l), a)| TraceCtx { scene: s, leaves: l, accel: a.as_ref(), max_depth: s.max_depth })
            .collect::<Vec<_>>();
        let max_depth = ls.scenes[0].max_depth;
        LodTracer { pixel_angle: 0.0, ctxs, p, lvl_max: ls.lvl_max, max_depth }
    }

    #[inline]
    fn level(&self, st: &RayState) -> u32 {
        level_of(st.lod, self.lvl_max)
    }

    fn root_state(&self) -> RayState {
        RayState { lod: self.p.force.unwrap_or(1.0), k: 1.0, d: 0.0, inside: Inside::default() }
    }

    /// Closest hit for a ray of level `lv`, honouring the enter/exit list; returns the hit
    /// and the level whose scene it belongs to.
    fn intersect(&self, ray: &Ray, lv: u32, st: &RayState, c: &mut Counters) -> Option<(Hit, u32)> {
        c.inc(Counter::lod_queries);
        c.add(Counter::lod_level_sum, lv as u64);
        let exc = st.inside.entries();
        if exc.iter().all(|e| e.1 as u32 == lv) {
            return self.ctxs[lv as usize].accel.intersect1(ray, c).map(|h| (h, lv));
        }
        c.inc(Counter::lod_exceptions);
        // Objects entered at another level: skipped at the ray's level, then each tested
        // alone at its entry level, nearest wins.
        let mut skip = [0u32; INSIDE_MAX];
        let mut n = 0;
        for e in exc.iter().filter(|e| e.1 as u32 != lv) {
            skip[n] = e.0;
            n += 1;
        }
        let mut best = self.ctxs[lv as usize].accel.intersect1_filtered(ray, InstFilter::Skip(&skip[..n]), c).map(|h| (h, lv));
        for &(inst, lo) in exc.iter().filter(|e| e.1 as u32 != lv) {
            let mut r = *ray;
            if let Some((b, _)) = &best {
                r.tfar = b.t;
            }
            if let Some(h) = self.ctxs[lo as usize].accel.intersect1_filtered(&r, InstFilter::Only(inst), c) {
                best = Some((h, lo as u32));
            }
        }
        best
    }

    fn radiance(&self, ray: &Ray, depth: u32, st: &RayState, c: &mut Counters) -> Vec3 {
        let lv = self.level(st);
        match self.intersect(ray, lv, st, c) {
            Some((h, lh)) => self.shade(ray, &h, lh, lv, depth, st, c),
            None => self.ctxs[0].scene.background,
        }
    }

    /// The child state of a ray spawned with strength factor `kx` (§3).
    fn child(&self, st: &RayState, kx: f32) -> RayState {
        let k = st.k * kx;
        let lod = match self.p.force {
            Some(x) => x,
            None if st.d > self.p.thres => st.lod * (1.0 - self.p.a_lod + self.p.a_lod * k),
            None => st.lod,
        };
        RayState { lod, k, d: st.d, inside: st.inside }
    }

    /// Shades a hit of a ray of level `depth` ≥ 1 (`lh`: the level scene of the hit, `lv`:
    /// the ray's own level, used for its shadow rays).
    #[allow(clippy::too_many_arguments)]
    fn shade(&self, ray: &Ray, hit: &Hit, lh: u32, lv: u32, depth: u32, st: &RayState, c: &mut Counters) -> Vec3 {
        let ctx = &self.ctxs[lh as usize];
        let shadow = &self.ctxs[lv as usize];
        let s = ctx.surface(ray, hit);
        let v = -ray.dir;
        let eps = s.eps;
        let p_out = s.p + s.ng * eps;
        let mut l = ctx.direct(&s, v, p_out, None, c, |r, c| shadow.accel.occluded1(r, c));
        if depth >= self.max_depth {
            return l;
        }
        let sec = secondary(&s, v);
        let kt = s.mat.transmit * luminance(s.mat.color);
        let kr = sec.reflect_w;
        let (do_t, do_r) = self.selective(depth, lv, st, sec.refract.is_some(), sec.reflect_w > 0.0, kr, kt, c);
        if do_t {
            let t = sec.refract.unwrap();
            let mut cs = self.child(st, kt);
            if s.front {
                cs.inside.enter(hit.inst, lv);
            } else {
                cs.inside.exit(hit.inst);
            }
            c.inc(Counter::rays_refract);
            let lt = self.radiance(&Ray::new(s.p - s.ng * eps, t), depth + 1, &cs, c);
            l += lt * s.mat.color * s.mat.transmit;
        }
        if do_r {
            let cs = self.child(st, kr);
            c.inc(Counter::rays_reflect);
            l += self.radiance(&Ray::new(p_out, sec.mirror), depth + 1, &cs, c) * sec.reflect_w;
        }
        l
    }

    /// Selective tracing (§4) at a hit of a ray of level `depth` on level `lv`: which of the
    /// transmitted and reflected children (`do_t`, `do_r`) are traced, the weaker dropped
    /// when the strengths `kt`, `kr` differ by more than the ratio.
    #[allow(clippy::too_many_arguments)]
    fn selective(&self, depth: u32, lv: u32, st: &RayState, do_t: bool, do_r: bool, kr: f32, kt: f32, c: &mut Counters) -> (bool, bool) {
        // "Provided that the LOD used is less than 100 %" (§4): the model, not the raw value.
        let below_full = match self.p.selective_on {
            SelectiveOn::Model => lv > 0,
            SelectiveOn::Value => st.lod < 1.0,
        };
        if self.p.selective && depth >= self.p.selective_level && below_full && do_t && do_r {
            if kr > self.p.selective_ratio * kt {
                c.inc(Counter::lod_rays_dropped);
                return (false, true);
            } else if kt > self.p.selective_ratio * kr {
                c.inc(Counter::lod_rays_dropped);
                return (true, false);
            }
        }
        (do_t, do_r)
    }

    /// Pass 1 for one primary ray and its hit: local shading and the distortion-buffer entry.
    fn pass1_cell(&self, ray: Ray, hit: Option<Hit>, c: &mut Counters) -> Cell<'a> {
        let mut cell = Cell { dir: ray.dir, l0: self.ctxs[0].scene.background, ..Cell::EMPTY };
        let Some(h) = hit else { return cell };
        let lv = self.level(&self.root_state());
        let ctx = &self.ctxs[lv as usize];
        let s = ctx.surface(&ray, &h);
        let v = -ray.dir;
        let p_out = s.p + s.ng * s.eps;
        cell.l0 = ctx.direct(&s, v, p_out, None, c, |r, c| ctx.accel.occluded1(r, c));
        if self.max_depth == 0 {
            return cell;
        }
        let sec = secondary(&s, v);
        if let Some(t) = sec.refract {
            cell.t = t;
            cell.has_t = true;
            cell.p_in = s.p - s.ng * s.eps;
        }
        if sec.reflect_w > 0.0 {
            cell.r = sec.mirror;
            cell.kr = sec.reflect_w;
            cell.p_out = p_out;
        }
        (cell.mat, cell.inst, cell.front) = (Some(s.mat), h.inst, s.front);
        if self.p.selector == Selector::Cone {
            cell.cone = self.cone_disparity(ctx, &ray, &h, &s, cell.r != Vec3::ZERO, cell.t != Vec3::ZERO);
        }
        cell
    }

    /// The ray-cone selector (beyond the paper; ray cones after Amanatides 1984 and
    /// Akenine-Möller et al. 2019): the primary cone of spread α (one pixel) has width
    /// w = α·t at the hit; the surface bends normals by Δn = κ·w across it (κ: the largest
    /// normal change per unit length along the triangle's edges); the outgoing cone spreads
    /// by α + 2Δn after reflection and by η·α + |1 − η|·Δn after refraction (first order,
    /// η the ratio of indices). The spread the surface *adds* over the pixel's own α, on both
    /// image axes, divided by 2π, is this selector's d — in the units of the paper's
    /// disparity (two neighbour angles over 2π), zero for a flat mirror.
    fn cone_disparity(&self, ctx: &TraceCtx, ray: &Ray, h: &Hit, s: &crate::baseline::shade::Surface, r: bool, t: bool) -> (f32, f32) {
        let leaf = &ctx.leaves[h.inst as usize];
        let mesh = &ctx.scene.meshes[leaf.mesh as usize];
        let [i0, i1, i2] = mesh.tris[h.prim as usize];
        let nm = glam::Mat3::from(leaf.normal_mat);
        let mut kappa = 0.0f32;
        for (a, b) in [(i0, i1), (i1, i2), (i2, i0)] {
            let dp = leaf.xform.transform_vector3(mesh.pos(a) - mesh.pos(b)).length();
            let dn = ((nm * mesh.normal(a)).normalize_or_zero() - (nm * mesh.normal(b)).normalize_or_zero()).length();
            if dp > 0.0 {
                kappa = kappa.max(dn / dp);
            }
        }
        let alpha = self.pixel_angle;
        let w = alpha * h.t * ray.dir.length();
        let dn = kappa * w;
        let tau = std::f32::consts::TAU;
        let dr = if r { 2.0 * (2.0 * dn) / tau } else { 0.0 };
        let dt = if t {
            let eta = if s.front { 1.0 / s.mat.ior } else { s.mat.ior };
            2.0 * ((eta * alpha + (1.0 - eta).abs() * dn) - alpha).max(0.0) / tau
        } else {
            0.0
        };
        (dr.clamp(0.0, 1.0), dt.clamp(0.0, 1.0))
    }

    /// Pass 2 for one primary sample: the level-1 sub-trees at the LODs from the disparities,
    /// spawned from what pass 1 left in the cell.
    fn pass2_cell(&self, cell: &Cell, d_r: f32, d_t: f32, c: &mut Counters) -> (Vec3, f32, f32) {
        let root = self.root_state();
        // No hit, or `max_depth` 0 (pass 1 then leaves `mat` empty).
        let Some(mat) = cell.mat else { return (cell.l0, 1.0, 1.0) };
        let lv = self.level(&root);
        let mut l = cell.l0;
        let lod1 = |d: f32| match self.p.force {
            Some(x) => x,
            None => root.lod * (1.0 - d).max(0.0).powf(self.p.f),
        };
        let (mut lr, mut lt) = (1.0, 1.0);
        // The primary hit's children too (`--lod-selective-level 0`; stop 80: pass 2 spawned
        // them without the rule, so level 0 rendered what level 1 renders).
        let kt = mat.transmit * luminance(mat.color);
        let (do_t, do_r) = self.selective(0, lv, &root, cell.has_t, cell.kr > 0.0, cell.kr, kt, c);
        if do_t {
            let mut inside = Inside::default();
            if cell.front {
                inside.enter(cell.inst, lv);
            }
            let st = RayState { lod: lod1(d_t), k: kt, d: d_t, inside };
            lt = st.lod;
            c.inc(Counter::rays_refract);
            let x = self.radiance(&Ray::new(cell.p_in, cell.t), 1, &st, c);
            l += x * mat.color * mat.transmit;
        }
        if do_r {
            let st = RayState { lod: lod1(d_r), k: cell.kr, d: d_r, inside: Inside::default() };
            lr = st.lod;
            c.inc(Counter::rays_reflect);
            l += self.radiance(&Ray::new(cell.p_out, cell.r), 1, &st, c) * cell.kr;
        }
        (l, lr, lt)
    }
}

/// Mean planar angle / 2π between a direction and its horizontal and vertical neighbours
/// (§2.2); a zero vector means "no ray here", and so does a non-finite one: a NaN would
/// otherwise pass through (1 − d)^f as LOD NaN and select the coarsest model, where
/// [`super::chain::level_of`] reads NaN as full detail.
pub fn disparity(d: Vec3, h: Option<Vec3>, v: Option<Vec3>) -> f32 {
    if d == Vec3::ZERO || !d.is_finite() {
        return 0.0;
    }
    let ang = |o: Option<Vec3>| o.filter(|x| *x != Vec3::ZERO && x.is_finite()).map(|x| d.dot(x).clamp(-1.0, 1.0).acos()).unwrap_or(0.0);
    ((ang(h) + ang(v)) / std::f32::consts::TAU).clamp(0.0, 1.0)
}

/// `--lod-net-disparity`: on each image axis the outgoing angle minus the incident rays'
/// angle, never below zero, summed over the two axes (/ 2π). Subtracting the sums instead let
/// an axis on which the surface converges the rays cancel the other's divergence: a saddle
/// whose rays spread by 0.1 rad horizontally and run parallel vertically, seen by rays 0.05
/// rad apart, measured 0 instead of 0.05/2π.
pub fn net_disparity(d: Vec3, h: Option<Vec3>, v: Option<Vec3>, inc: Vec3, inc_h: Option<Vec3>, inc_v: Option<Vec3>) -> f32 {
    let axis = |o: Option<Vec3>, i: Option<Vec3>| (disparity(d, o, None) - disparity(inc, i, None)).max(0.0);
    (axis(h, inc_h) + axis(v, inc_v)).clamp(0.0, 1.0)
}

pub struct LodRender {
    pub out: RenderOutput,
    pub maps: LodMaps,
    pub pass1_seconds: f64,
}

/// Renders one frame with `--method lod`.
pub fn render(tr: &mut LodTracer, cam: &CameraFrame, opts: &RenderOpts) -> Result<LodRender> {
    opts.validate()?;
    tr.p.validate()?;
    tr.pixel_angle = 2.0 * cam.s / opts.height as f32;
    let tr = &*tr;
    let pool = crate::core::thread_pool(opts.threads)?;
    let threads = pool.current_num_threads();
    let start = Instant::now();
    let cpu0 = crate::baseline::render::process_cpu_seconds();
    let (film, counters, maps, p1) = pool.install(|| two_pass(tr, cam, opts));
    let mut out = RenderOutput::timed(film, counters, start, cpu0, threads);
    if opts.aov && opts.spp > 1 {
        let ctx0 = &tr.ctxs[tr.level(&tr.root_state()) as usize];
        pool.install(|| crate::baseline::render::aov_probes(ctx0, cam, &mut out.film));
    }
    Ok(LodRender { out, maps, pass1_seconds: p1 })
}

/// Both passes run over bands of 16 image rows in parallel (rayon's work stealing balances
/// them), each band writing its own slice of the distortion buffer and of the film: no
/// scatter step. (Tiles with a per-tile result list and a scatter cost 22 % over Whitted on
/// `reflector`, 512², 4 spp; rows brought that down to the figure in the README; stop 83: a
/// band is walked in 16×16 blocks, Whitted's tile order, without a scatter.) Every sample
/// index has its own distortion buffer (a plane of one cell per pixel). When all `spp`
/// planes fit in [`ALL_PLANES_BUDGET`], one round fills them all and a pixel's samples are
/// traced back to back, as the Whitted tracer does (stop 83); otherwise the two passes run
/// once per sample index over a single plane, so memory stays that of the film at any
/// `--spp` (a buffer of all samples took 100 bytes per sample, 420 MB at 8×8 and 65536 spp,
/// and aborted where Whitted ran).
fn two_pass(tr: &LodTracer, cam: &CameraFrame, opts: &RenderOpts) -> (Film, Counters, LodMaps, f64) {
    let (w, h, spp) = (opts.width, opts.height, opts.spp);
    let wu = w as usize;
    let npix = (w * h) as usize;
    // Both passes visit the image in bands of BAND rows (one parallel task each), and a band
    // in blocks of TILE columns, block after block: the Whitted tracer's 16×16 tiles, whose
    // rays touch fewer BVH nodes between neighbours than a row of the whole width does (stop
    // 83; one task per row, as until then, cost cache misses: the same instructions ran up
    // to 10 % slower than Whitted's). The band is a contiguous slice of the buffer, the film
    // and the maps, so each task still writes its own slices, with no scatter step. TILE is
    // a multiple of the packet width K = 8, so `primary_row` forms the same packets.
    const BAND: usize = crate::baseline::render::TILE as usize;
    const _: () = assert!(BAND.is_multiple_of(crate::baseline::accel::K));
    // Planes per round: all `spp` when they fit the budget, else one (a round per sample
    // index). The planes are interleaved per pixel (cell `k·planes + o` is sample `o` of the
    // round at pixel k), so a band's cells stay one contiguous slice and a pixel's samples
    // sit side by side.
    let planes =
        if npix.saturating_mul(spp as usize).saturating_mul(std::mem::size_of::<Cell>()) <= ALL_PLANES_BUDGET { spp as usize } else { 1 };
    // `spp` ≥ 1 (`RenderOpts::validate`), so `planes` divides it: `spp` rounds or one.
    let rounds = spp as usize / planes;
    let band = BAND * wu;
    let blocks = || (0..w).step_by(BAND).map(move |x0| (x0, (x0 + BAND as u32).min(w)));
    let prog = Progress::new(2 * h.div_ceil(BAND as u32) as u64 * rounds as u64, &opts.label, opts.quiet);
    let ctx0 = &tr.ctxs[tr.level(&tr.root_state()) as usize];
    let merge = |mut a: Counters, b: Counters| {
        a.merge(&b);
        a
    };
    let mut buf = vec![Cell::EMPTY; npix * planes];
    let mut film = Film::new(w, h);
    // Sums over the samples (averaged at the end, in sample order as before).
    let mut maps = LodMaps {
        width: w,
        height: h,
        d_r: vec![0.0; npix],
        d_t: vec![0.0; npix],
        lod_r: vec![0.0; npix],
        lod_t: vec![0.0; npix],
        lod_min: vec![1.0; npix],
    };
    let mut counters = Counters::default();
    let mut pass1_seconds = 0.0;
    for round in 0..rounds {
        // Sample index of plane `o` in this round.
        let s0 = (round * planes) as u32;
        // Pass 1: level-0 rays (packets of K at one sample per pixel, as the Whitted tracer;
        // with several samples, a pixel's samples one after the other).
        let t0 = Instant::now();
        let c1 = buf
            .par_chunks_mut(band * planes)
            .zip(film.depth.par_chunks_mut(band))
            .zip(film.normal.par_chunks_mut(band))
            .enumerate()
            .map(|(b, ((cells, depth), normal))| {
                let mut c = Counters::default();
                let j0 = (b * BAND) as u32;
                for (x0, x1) in blocks() {
                    for jj in 0..(depth.len() / wu) as u32 {
                        let (j, row) = (j0 + jj, jj as usize * wu);
                        if spp == 1 {
                            primary_row(ctx0.accel, cam, j, x0, x1, opts.packet, &mut c, |i, ray, hit, c| {
                                let i = row + i as usize;
                                cells[i] = tr.pass1_cell(*ray, hit.copied(), c);
                                if opts.aov {
                                    (depth[i], normal[i]) = match hit {
                                        Some(hh) => (hh.t, ctx0.surface(ray, hh).ns),
                                        None => (f32::INFINITY, Vec3::ZERO),
                                    };
                                }
                            });
                        } else {
                            for i in x0..x1 {
                                let at = (row + i as usize) * planes;
                                for (o, cell) in cells[at..at + planes].iter_mut().enumerate() {
                                    let mut smp = Sampler::new(opts.seed, j * w + i, s0 + o as u32);
                                    let (u, v) = smp.next2();
                                    let ray = Ray::new(cam.eye, cam.dir_at(i as f32 + u, j as f32 + v));
                                    c.inc(Counter::rays_primary);
                                    c.inc(Counter::samples);
                                    let hit = ctx0.accel.intersect1(&ray, &mut c);
                                    *cell = tr.pass1_cell(ray, hit, &mut c);
                                }
                            }
                            // Depth and normal AOVs: `aov_probes`, after the timed render.
                        }
                    }
                }
                prog.tick();
                c
            })
            .reduce(Counters::default, merge);
        counters.merge(&c1);
        pass1_seconds += t0.elapsed().as_secs_f64();

        // Pass 2: disparities from the horizontal and vertical neighbours of the same plane
        // (same sample index), then the level-1 sub-trees.
        let buf = &buf;
        let at = |i: i64, j: i64, o: usize, r: bool| -> Option<usize> {
            if i < 0 || j < 0 || i >= w as i64 || j >= h as i64 {
                return None;
            }
            let k = (j as usize * wu + i as usize) * planes + o;
            let d = if r { buf[k].r } else { buf[k].t };
            (d != Vec3::ZERO).then_some(k)
        };
        let net = tr.p.net_disparity;
        let cone = tr.p.selector == Selector::Cone;
        // Disparities of plane `o` at pixel `k`.
        let disparity_at = |k: usize, o: usize| -> (f32, f32) {
            let cell = &buf[k * planes + o];
            if cone {
                return cell.cone;
            }
            let (i, j) = ((k % wu) as i64, (k / wu) as i64);
            let one = |r: bool| {
                let dir = |c: &Cell| if r { c.r } else { c.t };
                if dir(cell) == Vec3::ZERO {
                    return 0.0;
                }
                let hn = at(i + 1, j, o, r).or_else(|| at(i - 1, j, o, r));
                let vn = at(i, j + 1, o, r).or_else(|| at(i, j - 1, o, r));
                let (oh, ov) = (hn.map(|n| dir(&buf[n])), vn.map(|n| dir(&buf[n])));
                if net {
                    // Minus the divergence the incident rays already had, per axis.
                    net_disparity(dir(cell), oh, ov, cell.dir, hn.map(|n| buf[n].dir), vn.map(|n| buf[n].dir))
                } else {
                    disparity(dir(cell), oh, ov)
                }
            };
            (one(true), one(false))
        };
        let c2 = film
            .color
            .par_chunks_mut(band)
            .zip(maps.d_r.par_chunks_mut(band))
            .zip(maps.d_t.par_chunks_mut(band))
            .zip(maps.lod_r.par_chunks_mut(band))
            .zip(maps.lod_t.par_chunks_mut(band))
            .zip(maps.lod_min.par_chunks_mut(band))
            .enumerate()
            .map(|(b, (((((color, dr_row), dt_row), lr_row), lt_row), min_row))| {
                let mut c = Counters::default();
                let k0 = b * band;
                for (x0, x1) in blocks() {
                    for row in (0..color.len()).step_by(wu) {
                        for i in row + x0 as usize..row + x1 as usize {
                            let k = k0 + i;
                            // The samples in index order, so every sum adds them in the
                            // order the one-plane rounds do: the same bits either way.
                            for o in 0..planes {
                                let (dr, dt) = disparity_at(k, o);
                                let (col, lr, lt) = tr.pass2_cell(&buf[k * planes + o], dr, dt, &mut c);
                                color[i] += col;
                                dr_row[i] += dr;
                                dt_row[i] += dt;
                                lr_row[i] += lr;
                                lt_row[i] += lt;
                                min_row[i] = min_row[i].min(lr).min(lt);
                            }
                        }
                    }
                }
                prog.tick();
                c
            })
            .reduce(Counters::default, merge);
        counters.merge(&c2);
    }
    prog.finish();
    if spp > 1 {
        film.color.iter_mut().for_each(|c| *c /= spp as f32);
    }
    let inv = 1.0 / spp as f32;
    for m in [&mut maps.d_r, &mut maps.d_t, &mut maps.lod_r, &mut maps.lod_t] {
        m.iter_mut().for_each(|x| *x *= inv);
    }
    (film, counters, maps, pass1_seconds)
}

/// The most memory the distortion buffer may take to hold every sample index at once (`pixels ×
/// spp × size_of::<Cell>()`, about 100 bytes a cell): 256 MiB, enough for 512² at 8 spp or
/// 1024² at 2 spp, while a huge `--spp` (8×8 at 65536 spp, which a buffer of all samples once
/// aborted) stays on one plane. Beyond it the passes go one sample index at a time over one
/// plane, as large as the film's colour. Within it a pixel's samples and their secondary rays
/// run back to back and touch the same BVH nodes (the jittered samples of one pixel are more
/// coherent than neighbouring pixels, all the more after bumpy glass): stop 83, `chessboard`
/// 512², 4 spp, one thread, the LOD frame went from 5.49–5.69 s to 5.12–5.27 s (−6.7 % on the
/// means of four interleaved runs each; `force=1` −5.2 %; Whitted 5.45–5.83 s), with the
/// same image, maps and counters.
const ALL_PLANES_BUDGET: usize = 256 << 20;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disparity_of_parallel_rays_is_zero_and_opposite_is_half() {
        let d = Vec3::new(0.0, 0.0, 1.0);
        assert_eq!(disparity(d, Some(d), Some(d)), 0.0);
        assert!((disparity(d, Some(-d), None) - 0.5).abs() < 1e-6);
        assert!((disparity(d, Some(-d), Some(-d)) - 1.0).abs() < 1e-6);
        assert_eq!(disparity(Vec3::ZERO, Some(d), Some(d)), 0.0);
        let e = Vec3::new(1.0, 0.0, 1.0).normalize();
        let x = disparity(d, Some(e), None);
        assert!((x - 0.125).abs() < 1e-6, "{x}");
        // A non-finite neighbour is no neighbour; a non-finite ray has no disparity (full
        // detail, as `level_of` reads NaN), never NaN.
        let nan = Vec3::new(f32::NAN, 0.0, 1.0);
        assert_eq!(disparity(d, Some(nan), Some(e)), x);
        assert_eq!(disparity(nan, Some(d), Some(e)), 0.0);
        assert_eq!(disparity(d, Some(Vec3::splat(f32::INFINITY)), None), 0.0);
    }

    /// A ray that entered an object at one level leaves it at that level (Fig. 3), whatever
    /// its own level has become; without the entry the coarse model is hit.
    #[test]
    fn exit_is_tested_at_the_entry_level() {
        use crate::baseline::accel::{self, AccelKind};
        use crate::lod::chain::{ChainParams, LodScenes};
        use crate::scene::{builtin::uv_sphere, Scene, Target};
        let mut sc = Scene::empty("ball");
        let m = sc.add_mesh(uv_sphere(24, 48, 0));
        sc.instance(Target::Mesh(m), glam::Affine3A::IDENTITY, None);
        // A second object touching the ball from outside (the close-contact case).
        sc.instance(Target::Mesh(m), glam::Affine3A::from_translation(Vec3::new(2.0, 0.0, 0.0)), None);
        let ls = LodScenes::build(&sc, &ChainParams { levels: 8, distance: None }).unwrap();
        let leaves: Vec<_> = ls.scenes.iter().map(|s| s.leaf_instances().unwrap()).collect();
        let accels: Vec<_> = ls.scenes.iter().map(|s| accel::build(AccelKind::Bvh, s).unwrap()).collect();
        let p = LodParams::default();
        let tr = LodTracer::new(&ls, &leaves, &accels, &p);
        let mut c = Counters::default();
        let mut smp = Sampler::new(1, 2, 3);
        let mut differ = 0;
        for _ in 0..500 {
            let (a, b) = smp.next2();
            let z = 1.0 - 2.0 * a;
            let r = (1.0 - z * z).max(0.0).sqrt();
            let d = Vec3::new(r * (std::f32::consts::TAU * b).cos(), r * (std::f32::consts::TAU * b).sin(), z);
            let ray = Ray::new(Vec3::ZERO, d);
            let mut inside = Inside::default();
            inside.enter(0, 0);
            let coarse = RayState { lod: 0.05, k: 0.5, d: 0.1, inside: Inside::default() };
            let entered = RayState { inside, ..coarse };
            let lv = tr.level(&coarse);
            assert_eq!(lv, 6);
            let (h0, l0) = tr.intersect(&ray, lv, &entered, &mut c).expect("exit hit");
            assert_eq!((l0, h0.inst), (0, 0));
            let fine = accels[0].intersect1(&ray, &mut c).unwrap();
            assert_eq!(h0.t, fine.t);
            let (h6, l6) = tr.intersect(&ray, lv, &coarse, &mut c).expect("coarse hit");
            assert_eq!(l6, 6);
            assert_eq!(h6.t, accels[6].intersect1(&ray, &mut c).unwrap().t);
            differ += (h6.t != h0.t) as u32;
        }
        // The levels are different models, so the test means something.
        assert!(differ > 400, "{differ}");
    }

    /// The net disparity subtracts the incident angle per axis, as the module header says: a
    /// converging axis does not cancel a diverging one.
    #[test]
    fn net_disparity_is_taken_per_axis() {
        let z = Vec3::Z;
        let rot = |a: f32, axis: Vec3| glam::Quat::from_axis_angle(axis, a) * z;
        // Incident neighbours 0.05 rad apart on both axes; outgoing 0.1 rad apart
        // horizontally, parallel vertically (a saddle-like surface).
        let (ih, iv) = (rot(0.05, Vec3::Y), rot(0.05, Vec3::X));
        let (oh, ov) = (rot(0.1, Vec3::Y), z);
        let got = net_disparity(z, Some(oh), Some(ov), z, Some(ih), Some(iv));
        let want = 0.05 / std::f32::consts::TAU;
        assert!((got - want).abs() < 2e-4, "net disparity {got}, want {want}");
        // A flat mirror (outgoing angles equal the incident ones) adds nothing.
        assert!(net_disparity(z, Some(ih), Some(iv), z, Some(ih), Some(iv)) < 1e-6);
        // No neighbour on an axis: that axis adds nothing.
        assert!((net_disparity(z, Some(oh), None, z, Some(ih), None) - want).abs() < 2e-4);
    }

    #[test]
    fn inside_list_enters_and_exits() {
        let mut l = Inside::default();
        l.enter(3, 1);
        l.enter(5, 2);
        l.enter(3, 4); // already inside: keeps the first level
        assert_eq!(l.entries(), &[(3, 1), (5, 2)]);
        l.exit(3);
        assert_eq!(l.entries(), &[(5, 2)]);
        l.exit(9);
        assert_eq!(l.entries(), &[(5, 2)]);
    }
}
