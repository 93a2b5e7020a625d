//! Embree 3.13.5 back-end (`--accel embree`): the ground-truth triangle intersector of the
//! conventional baseline and of `lodtrace verify`.
//!
//! Two levels, as the scene model (see `scene` docs): one Embree scene per unique mesh
//! (triangle geometry, shared SoA positions gathered into Embree's FLOAT3 buffer) and one
//! top-level scene holding an instance geometry per leaf instance, attached with geometry ID
//! = leaf-instance index, so `RTCHit::instID[0]` is [`Hit::inst`] directly.
//!
//! Packets: [`Accel::intersect8`]/[`Accel::occluded8`] go through `rtcIntersect8` /
//! `rtcOccluded8` with a coherent context (primary packets). `intersect_stream` is
//! `rtcIntersect1M`, the stream API, for `verify` and the traversal benchmark.
//!
//! Filtered queries ([`Accel::intersect1_filtered`], the per-ray LOD tracer's enter/exit
//! list) test the instance filter in an Embree context filter function
//! (`RTC_SCENE_FLAG_CONTEXT_FILTER_FUNCTION` on every scene; unfiltered queries pass no filter):
//! the trait's default, which steps `tnear` past each rejected hit, lost an admitted hit at
//! the same distance (a floor under a box's bottom face).
//!
//! Robust mode (`RTC_SCENE_FLAG_ROBUST`, watertight triangle test) is used by `verify` and,
//! since stop 54, for rendering too: Embree's default fast mode let primary rays through the
//! shared edge of two floor triangles 1e5 units wide seen from a few units away (a user's
//! "infinite ground": two background pixels on the seam of a 512×384 frame). Robust mode costs
//! `complex` at 640×480 about 8 % of a Whitted frame (0.175 / 0.168 s against 0.157 / 0.160 s)
//! and 12 % of a distributed one at `spp=16` (1.830 / 1.792 s against 1.619 / 1.623 s; `bench
//! --repeat 3`, two runs each, alternating). `LODTRACE_EMBREE_FAST=1` renders in fast mode, which `verify --accel
//! embree` checks against the robust mode. The ISA can be pinned with the environment
//! variable `LODTRACE_EMBREE_ISA` (e.g. `sse4.2`, `avx2`), passed as Embree's `isa=` device
//! option; memory is counted by a device memory-monitor callback.
//!
//! Only the raw `embree3::sys` bindings are used: the safe wrapper of the crate does not
//! expose instance IDs of hits in packets or the memory monitor.

use super::accel::{Accel, Hit, InstFilter, Ray, K};
use crate::core::stats::{Counter, Counters};
use crate::error::{Error, Result};
use crate::scene::Scene;
use embree3::sys::*;
use std::ffi::CString;
use std::os::raw::c_void;
use std::sync::atomic::{AtomicIsize, Ordering};

const INVALID_ID: u32 = u32::MAX;

pub struct EmbreeAccel {
    device: RTCDevice,
    top: RTCScene,
    meshes: Vec<RTCScene>,
    /// Bytes Embree holds, as reported by the memory monitor (boxed: its address is the
    /// callback's user pointer).
    mem: Box<AtomicIsize>,
    robust: bool,
}

// Embree scenes are immutable after commit and its query functions are thread-safe.
unsafe impl Send for EmbreeAccel {}
unsafe impl Sync for EmbreeAccel {}

unsafe extern "C" fn memory_monitor(user: *mut c_void, bytes: isize, _post: bool) -> bool {
    let m = &*(user as *const AtomicIsize);
    m.fetch_add(bytes, Ordering::Relaxed);
    true
}

#[repr(C, align(32))]
struct Valid8([i32; 8]);

/// An intersect context extended with an instance filter: Embree hands the context pointer
/// to the context filter function, so data placed after it travels along (Embree's
/// documented way to pass per-query data).
#[repr(C)]
struct FilterContext<'a> {
    ctx: RTCIntersectContext,
    filter: InstFilter<'a>,
}

/// Context filter: rejects the hits of leaf instances the query's filter does not admit.
unsafe extern "C" fn instance_filter(args: *const RTCFilterFunctionNArguments) {
    let a = &*args;
    // SAFETY: only installed by `intersect1_filtered`, whose context is a `FilterContext`.
    let fc = &*(a.context as *const FilterContext);
    let n = a.N as usize;
    for i in 0..n {
        // RTCHitN is SoA: field k of lane i at ((u32*)hit)[k·N + i]; instID[0] is field 7
        // (after Ng_x, Ng_y, Ng_z, u, v, primID, geomID).
        let inst = *(a.hit as *const u32).add(7 * n + i);
        if *a.valid.add(i) != 0 && !fc.filter.admits(inst) {
            *a.valid.add(i) = 0;
        }
    }
}

fn context(coherent: bool) -> RTCIntersectContext {
    RTCIntersectContext {
        flags: if coherent { RTCIntersectContextFlags::COHERENT } else { RTCIntersectContextFlags::INCOHERENT },
        filter: None,
        instID: [INVALID_ID],
    }
}

/// The device configuration for a build on a pool of `threads` on a machine of `cores`:
/// Embree builds on its own TBB workers, one per core, whatever pool it is called from, so a
/// run on fewer threads than cores (`--threads 1`, bench `threads=1`) limits them
/// (`threads=N`) for its build to be timed on the threads the other back-ends get (review
/// finding, stop 79: strace showed an extra worker in a `--threads 1` build). TBB serves
/// Embree alone in this process, so the limit, which TBB applies process-wide while the
/// device lives, reaches nothing else.
fn device_config(threads: usize, cores: usize) -> String {
    let mut c = String::from("verbose=0");
    if threads > 0 && threads < cores {
        c.push_str(&format!(",threads={threads}"));
    }
    c
}

fn error_text(e: RTCError) -> &'static str {
    match e {
        RTCError::NONE => "no error",
        RTCError::UNKNOWN => "unknown error",
        RTCError::INVALID_ARGUMENT => "invalid argument",
        RTCError::INVALID_OPERATION => "invalid operation",
        RTCError::OUT_OF_MEMORY => "out of memory",
        RTCError::UNSUPPORTED_CPU => "unsupported CPU",
        RTCError::CANCELLED => "cancelled",
    }
}

impl EmbreeAccel {
    /// For rendering: robust (watertight) mode, unless the environment variable
    /// `LODTRACE_EMBREE_FAST=1` asks for Embree's default fast mode (see the module header).
    pub fn build(scene: &Scene) -> Result<Self> {
        Self::build_with(scene, std::env::var("LODTRACE_EMBREE_FAST").map_or(true, |v| v != "1"))
    }

    /// `robust = true` sets `RTC_SCENE_FLAG_ROBUST` on every scene (watertight, no
    /// cracks between neighbouring triangles), as `verify` needs.
    pub fn build_with(scene: &Scene, robust: bool) -> Result<Self> {
        let leaves = scene.leaf_instances()?;
        if leaves.is_empty() {
            return Err(Error::Scene("nothing to build an Embree scene over".into()));
        }
        let mut config = device_config(rayon::current_num_threads(), std::thread::available_parallelism().map_or(0, |n| n.get()));
        // Empty counts as unset (as `LODTRACE_CACHE` and `LODTRACE_ASSETS`): `isa=` made
        // Embree refuse the device, "cannot create device (unknown error)".
        if let Some(isa) = std::env::var("LODTRACE_EMBREE_ISA").ok().filter(|v| !v.is_empty()) {
            if !isa.chars().all(|c| c.is_ascii_alphanumeric() || c == '.' || c == '_') {
                return Err(Error::Usage(format!("LODTRACE_EMBREE_ISA='{isa}' is not an ISA name")));
            }
            config.push_str(&format!(",isa={isa}"));
        }
        let cfg = CString::new(config).expect("no NUL in config");
        // SAFETY: plain Embree API calls on objects created here; every object is released
        // in Drop (or below on error).
        unsafe {
            let device = rtcNewDevice(cfg.as_ptr());
            if device.is_null() {
                return Err(Error::Accel(format!(
                    "Embree: cannot create device ({})",
                    error_text(rtcGetDeviceError(std::ptr::null_mut()))
                )));
            }
            let mem = Box::new(AtomicIsize::new(0));
            rtcSetDeviceMemoryMonitorFunction(device, Some(memory_monitor), &*mem as *const AtomicIsize as *mut c_void);
            let mut acc = EmbreeAccel { device, top: std::ptr::null_mut(), meshes: Vec::new(), mem, robust };
            let flags = RTCSceneFlags::CONTEXT_FILTER_FUNCTION | if robust { RTCSceneFlags::ROBUST } else { RTCSceneFlags::NONE };

            for mesh in &scene.meshes {
                let s = rtcNewScene(device);
                acc.meshes.push(s);
                rtcSetSceneFlags(s, flags);
                let g = rtcNewGeometry(device, RTCGeometryType::TRIANGLE);
                let nv = mesh.vertex_count();
                let nt = mesh.tri_count();
                let vb = rtcSetNewGeometryBuffer(g, RTCBufferType::VERTEX, 0, RTCFormat::FLOAT3, 12, nv) as *mut f32;
                let ib = rtcSetNewGeometryBuffer(g, RTCBufferType::INDEX, 0, RTCFormat::UINT3, 12, nt) as *mut u32;
                if vb.is_null() || ib.is_null() {
                    rtcReleaseGeometry(g);
                    return Err(acc.device_error("allocating mesh buffers"));
                }
                let v = std::slice::from_raw_parts_mut(vb, 3 * nv);
                for i in 0..nv {
                    v[3 * i] = mesh.px[i];
                    v[3 * i + 1] = mesh.py[i];
                    v[3 * i + 2] = mesh.pz[i];
                }
                let ix = std::slice::from_raw_parts_mut(ib, 3 * nt);
                for (t, tri) in mesh.tris.iter().enumerate() {
                    ix[3 * t..3 * t + 3].copy_from_slice(tri);
                }
                rtcCommitGeometry(g);
                rtcAttachGeometryByID(s, g, 0);
                rtcReleaseGeometry(g);
                rtcCommitScene(s);
                acc.check("building a mesh scene")?;
            }

            let top = rtcNewScene(device);
            acc.top = top;
            rtcSetSceneFlags(top, flags);
            for (i, l) in leaves.iter().enumerate() {
                let g = rtcNewGeometry(device, RTCGeometryType::INSTANCE);
                rtcSetGeometryInstancedScene(g, acc.meshes[l.mesh as usize]);
                // FLOAT3X4_COLUMN_MAJOR: the three columns of the linear part, then the translation.
                let m = l.xform.matrix3;
                let t = l.xform.translation;
                let cols: [f32; 12] = [
                    m.x_axis.x, m.x_axis.y, m.x_axis.z, m.y_axis.x, m.y_axis.y, m.y_axis.z, m.z_axis.x, m.z_axis.y, m.z_axis.z, t.x, t.y,
                    t.z,
                ];
                rtcSetGeometryTransform(g, 0, RTCFormat::FLOAT3X4_COLUMN_MAJOR, cols.as_ptr() as *const c_void);
                rtcCommitGeometry(g);
                rtcAttachGeometryByID(top, g, i as u32);
                rtcReleaseGeometry(g);
            }
            rtcCommitScene(top);
            acc.check("building the instance scene")?;
            Ok(acc)
        }
    }

    fn device_error(&self, what: &str) -> Error {
        // SAFETY: valid device.
        let e = unsafe { rtcGetDeviceError(self.device) };
        Error::Accel(format!("Embree: {what}: {}", error_text(e)))
    }

    fn check(&self, what: &str) -> Result<()> {
        // SAFETY: valid device.
        let e = unsafe { rtcGetDeviceError(self.device) };
        if e == RTCError::NONE {
            Ok(())
        } else {
            Err(Error::Accel(format!("Embree: {what}: {}", error_text(e))))
        }
    }

    pub fn is_robust(&self) -> bool {
        self.robust
    }

    /// Closest hits of many independent rays through Embree's stream API (`rtcIntersect1M`),
    /// in chunks of 256 rays; invalid rays (see [`Ray::is_valid`]) are misses.
    pub fn intersect_stream(&self, rays: &[Ray], out: &mut [Option<Hit>], c: &mut Counters) {
        assert_eq!(rays.len(), out.len());
        const M: usize = 256;
        let mut buf: Vec<RTCRayHit> = Vec::with_capacity(M);
        let mut idx: Vec<usize> = Vec::with_capacity(M);
        for (rs, os) in rays.chunks(M).zip(out.chunks_mut(M)) {
            buf.clear();
            idx.clear();
            for (i, r) in rs.iter().enumerate() {
                os[i] = None;
                if r.is_valid() {
                    buf.push(ray_hit(r));
                    idx.push(i);
                }
            }
            if buf.is_empty() {
                continue;
            }
            let mut ctx = context(false);
            // SAFETY: buf holds buf.len() initialised, 16-byte aligned RTCRayHit.
            unsafe { rtcIntersect1M(self.top, &mut ctx, buf.as_mut_ptr(), buf.len() as u32, std::mem::size_of::<RTCRayHit>()) };
            for (rh, &i) in buf.iter().zip(&idx) {
                os[i] = to_hit(rh);
            }
        }
        c.add(Counter::rays_verify, rays.len() as u64);
    }
}

#[inline]
fn ray_hit(r: &Ray) -> RTCRayHit {
    RTCRayHit {
        ray: RTCRay {
            org_x: r.org.x,
            org_y: r.org.y,
            org_z: r.org.z,
            tnear: r.tnear.max(0.0),
            dir_x: r.dir.x,
            dir_y: r.dir.y,
            dir_z: r.dir.z,
            time: 0.0,
            tfar: r.tfar,
            mask: u32::MAX,
            id: 0,
            flags: 0,
        },
        hit: RTCHit { Ng_x: 0.0, Ng_y: 0.0, Ng_z: 0.0, u: 0.0, v: 0.0, primID: INVALID_ID, geomID: INVALID_ID, instID: [INVALID_ID] },
    }
}

#[inline]
fn to_hit(rh: &RTCRayHit) -> Option<Hit> {
    (rh.hit.geomID != INVALID_ID).then(|| Hit { t: rh.ray.tfar, u: rh.hit.u, v: rh.hit.v, prim: rh.hit.primID, inst: rh.hit.instID[0] })
}

impl Accel for EmbreeAccel {
    fn name(&self) -> &'static str {
        "embree"
    }

    fn intersect1(&self, ray: &Ray, _c: &mut Counters) -> Option<Hit> {
        if !ray.is_valid() {
            return None;
        }
        let mut rh = ray_hit(ray);
        let mut ctx = context(false);
        // SAFETY: committed scene, initialised ray-hit.
        unsafe { rtcIntersect1(self.top, &mut ctx, &mut rh) };
        to_hit(&rh)
    }

    fn intersect1_filtered(&self, ray: &Ray, filter: InstFilter, c: &mut Counters) -> Option<Hit> {
        if matches!(filter, InstFilter::All) {
            return self.intersect1(ray, c);
        }
        if !ray.is_valid() {
            return None;
        }
        let mut rh = ray_hit(ray);
        let mut fc = FilterContext { ctx: context(false), filter };
        fc.ctx.filter = Some(instance_filter);
        // SAFETY: committed scene, initialised ray-hit; `fc` outlives the call.
        unsafe { rtcIntersect1(self.top, &mut fc.ctx, &mut rh) };
        to_hit(&rh)
    }

    fn occluded1(&self, ray: &Ray, _c: &mut Counters) -> bool {
        if !ray.is_valid() {
            return false;
        }
        let mut r = ray_hit(ray).ray;
        let mut ctx = context(false);
        // SAFETY: committed scene, initialised ray.
        unsafe { rtcOccluded1(self.top, &mut ctx, &mut r) };
        r.tfar == f32::NEG_INFINITY
    }

    fn intersect8(&self, rays: &[Ray; K], valid: u8, out: &mut [Option<Hit>; K], _c: &mut Counters) {
        let (mut rh, mask) = packet(rays, valid);
        for (i, o) in out.iter_mut().enumerate() {
            if valid & (1 << i) != 0 {
                *o = None;
            }
        }
        if mask.0.iter().all(|&m| m == 0) {
            return;
        }
        let mut ctx = context(true);
        // SAFETY: 32-byte aligned valid mask and packet, committed scene.
        unsafe { rtcIntersect8(mask.0.as_ptr(), self.top, &mut ctx, &mut rh) };
        for (i, o) in out.iter_mut().enumerate() {
            if mask.0[i] != 0 && rh.hit.geomID[i] != INVALID_ID {
                *o = Some(Hit { t: rh.ray.tfar[i], u: rh.hit.u[i], v: rh.hit.v[i], prim: rh.hit.primID[i], inst: rh.hit.instID[0][i] });
            }
        }
    }

    fn occluded8(&self, rays: &[Ray; K], valid: u8, out: &mut [bool; K], _c: &mut Counters) {
        let (mut rh, mask) = packet(rays, valid);
        for (i, o) in out.iter_mut().enumerate() {
            if valid & (1 << i) != 0 {
                *o = false;
            }
        }
        if mask.0.iter().all(|&m| m == 0) {
            return;
        }
        let mut ctx = context(false);
        // SAFETY: as above.
        unsafe { rtcOccluded8(mask.0.as_ptr(), self.top, &mut ctx, &mut rh.ray) };
        for (i, o) in out.iter_mut().enumerate() {
            if mask.0[i] != 0 {
                *o = rh.ray.tfar[i] == f32::NEG_INFINITY;
            }
        }
    }

    fn memory_bytes(&self) -> usize {
        self.mem.load(Ordering::Relaxed).max(0) as usize
    }
}

/// SoA packet of the valid lanes; invalid rays (see [`Ray::is_valid`]) are masked off.
fn packet(rays: &[Ray; K], valid: u8) -> (RTCRayHit8, Valid8) {
    // SAFETY: all-zero is a valid bit pattern for these plain-old-data structs.
    let mut rh: RTCRayHit8 = unsafe { std::mem::zeroed() };
    let mut mask = Valid8([0; 8]);
    for (i, r) in rays.iter().enumerate() {
        let on = valid & (1 << i) != 0 && r.is_valid();
        mask.0[i] = if on { -1 } else { 0 };
        rh.ray.org_x[i] = r.org.x;
        rh.ray.org_y[i] = r.org.y;
        rh.ray.org_z[i] = r.org.z;
        rh.ray.dir_x[i] = if on { r.dir.x } else { 1.0 };
        rh.ray.dir_y[i] = if on { r.dir.y } else { 0.0 };
        rh.ray.dir_z[i] = if on { r.dir.z } else { 0.0 };
        rh.ray.tnear[i] = if on { r.tnear.max(0.0) } else { 0.0 };
        rh.ray.tfar[i] = if on { r.tfar } else { -1.0 };
        rh.ray.mask[i] = u32::MAX;
        rh.hit.geomID[i] = INVALID_ID;
        rh.hit.primID[i] = INVALID_ID;
        rh.hit.instID[0][i] = INVALID_ID;
        if !on {
            rh.ray.org_x[i] = 0.0;
            rh.ray.org_y[i] = 0.0;
            rh.ray.org_z[i] = 0.0;
        }
    }
    (rh, mask)
}

impl Drop for EmbreeAccel {
    fn drop(&mut self) {
        // SAFETY: objects created by build_with, released once.
        unsafe {
            if !self.top.is_null() {
                rtcReleaseScene(self.top);
            }
            for &s in &self.meshes {
                rtcReleaseScene(s);
            }
            rtcReleaseDevice(self.device);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fewer threads than cores limit Embree's own workers; a run on every core leaves its
    /// default (one per core).
    #[test]
    fn embree_builds_on_the_runs_threads() {
        assert_eq!(device_config(1, 2), "verbose=0,threads=1");
        assert_eq!(device_config(3, 8), "verbose=0,threads=3");
        assert_eq!(device_config(2, 2), "verbose=0");
        assert_eq!(device_config(4, 0), "verbose=0");
    }
}
