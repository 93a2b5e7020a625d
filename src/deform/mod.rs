//! Adams et al. 2005, *Efficient Raytracing of Deforming Point-Sampled Surfaces* (Computer
//! Graphics Forum 24(3), Eurographics 2005): surfels embedded in a simulation (§3), a
//! bounding-sphere hierarchy updated lazily under deformation (§4.1), MLS ray–surface intersection (§4.2.1),
//! per-ray caching of the hit node (§4.2.2), clipping for sharp edges (§4.3), and the
//! shadow-ray optimisation (§4.4).
//!
//! # Modules
//! - [`surfel`] surfel models and collections with clipping relations; sampling meshes;
//!   [`ply`] point files.
//! - [`sim`] the physical model (meshless shape matching with clusters, collisions).
//! - [`displace`] Eq. 1–2 and the optimal rigid transform of Eq. 10.
//! - [`tree`] hierarchy build (median split, [`miniball`]), Eq. 3–4, 9, 11, f32x8 sphere
//!   kernels with their scalar references.
//! - [`object`] the per-model precomputation (§4.4); [`mls`] Eq. 12 and the clipping test;
//!   [`trace`] the per-frame tracer, which finds the objects along a ray with [`top`], a
//!   sphere tree over their roots; [`sequences`] the four built-in animations and the
//!   default drop for any mesh; [`knn`] static k-nearest-neighbour queries.
//!
//! # Using it (what `lodtrace animate` calls)
//! ```no_run
//! use lodtrace::deform::*;
//! use lodtrace::baseline::accel::Ray;
//! use lodtrace::core::stats::Counters;
//! # fn main() -> Result<(), DeformError> {
//! // 1. A sequence: built-in, or any mesh dropped onto a floor.
//! let mut seq = Sequence::builtin("elastic-balls", &SequenceOptions::default())?;
//! //    (or: Sequence::from_mesh(&lodtrace::scene::load::load_mesh(path, 0)?, &opts)?)
//! // 2. Optionally record the motion so benches replay identical frames (serde).
//! let rec: Recording = seq.record(seq.frames)?;
//! // 3. A tracer over the sequence's objects, in one of the update modes.
//! let mut tracer = DeformTracer::new(&seq.scene, UpdateMode::LazyCache, TraceParams::default())?;
//! tracer.set_cache_slots(512 * 384); // one per pixel (LazyCache)
//! for frame in &rec.frames {
//!     tracer.begin_frame(frame)?; // &mut self: between frames only
//!     // Per pixel, from any number of threads (`&self`):
//!     let mut ctr = Counters::default();
//!     let mut dc = DeformCounters::default();
//!     let ray = Ray::new(seq.camera.eye, glam::Vec3::NEG_Z);
//!     if let Some(hit) = tracer.intersect_ex(&ray, Some(0 /* pixel index */), &mut ctr, &mut dc) {
//!         let _ = (hit.t, hit.p, hit.n, hit.collection); // shade with Collection::color etc.
//!     }
//!     let _shadow = tracer.occluded(&Ray::segment(ray.org, ray.dir, 1e-3, 10.0), &mut ctr);
//!     // After the frame's rays:
//!     let _fs: FrameStats = tracer.frame_stats(); // nodes/surfels updated, update time
//!     let _ratios: Vec<LevelRatio> = tracer.radius_ratios(64); // vs tightest spheres
//! }
//! # Ok(()) }
//! ```
//! - [`Ray`](crate::baseline::accel::Ray) is the crate's ray (`t` in multiples of `dir`).
//! - `Counters` gets `node_tests` (sphere tests) and `surfel_tests` (leaf ellipse tests);
//!   [`DeformCounters`] has the paper's quantities (MLS iterations, cache hits, clipping).
//! - Hits are identical across modes and thread counts (see [`trace`] docs), so the modes
//!   can be compared image against image; only the work differs.
//! - Scene glue: `Sequence::world.colliders` are the static planes/boxes to render;
//!   `Sequence::camera` a suggested view; `SurfelObject::model.collections[c].color`
//!   a colour per surface. The tracer handles only the deforming objects.
//!
//! # Deviations from the paper (details in each module)
//! - Physics: shape matching with overlapping clusters \[MHTG05\] instead of \[MKN*04\]'s
//!   continuum mechanics; the node displacement gradient of Eq. 1 is an MLS fit over node
//!   neighbourhoods (as in \[MKN*04\]) computed from the node positions each frame. Eq. 1 uses
//!   `d = x_i − x_j` (first-order Taylor about the node); the paper's `d_{x,y} = y − x`
//!   read literally has the opposite sign ([`displace`]).
//! - Spheres bound the surfel *ellipses*, not only their centres, and B_j of Eq. 9 carries
//!   the ellipse radius term (so leaf hits are never culled by an ancestor).
//! - Eq. 9 is evaluated twice per node, the paper's form and a form re-centred at the sphere
//!   centre (same A_j, a second precomputed B'_j), and the smaller is used ([`tree`]).
//! - Eq. 9 also takes the partition-of-unity maxima (max_j instead of Σ_j A_j) and factors
//!   out each node's own rotation (the paper's §6 suggestion) when that is smaller ([`tree`]).
//! - Eq. 11 is re-evaluated at every descent (not once), so tightening propagates upwards.
//! - `animate --bound paper` (`TraceParams::recentred_bound`, `node_rotation`,
//!   `recentre_eq11` off) drops the three additions above and gives Eq. 9 and Eq. 11 as
//!   written; with `--exact-below 0` that is the paper's update throughout.
//! - The MLS support of a surfel (§4.2.1, fixed 16-surfel neighbourhoods) widens with the
//!   local stretch of the deformation, at most 3× (`TraceParams::max_support_stretch`,
//!   `animate --support-stretch`; 1 = the rest-pose support, the paper's): a stretched
//!   surface otherwise leaves too few neighbours inside the support.
//! - Beyond the paper: the instance tree over the objects' root spheres ([`top`]), rebuilt
//!   every frame, so that a ray does not test all 40 balls of `elastic-balls`.
//! - Beyond the paper: `UpdateMode::Auto`, per frame a rebuild or the lazy update, whichever
//!   was cheaper when last tried (§6 leaves such a heuristic to future work).
//! - Beyond the paper: `UpdateMode::Refit`, an obvhs BVH2 over the surfels' leaf balls,
//!   refitted every frame — the alternative a user would try today ([`trace`]).
//! - Centre support (Eq. 3) widened beyond R when fewer than k listed nodes lie within R.
//! - The median split keeps trees balanced (19 levels for 180k surfels, paper 23 for 170k).
//! - Sphere tests are conservative (widened by a rounding bound), and ellipse/MLS tests run
//!   over the ray's whole interval, so hits are identical in all modes ([`trace`]).
//! - Traversal is front to back (nearer child first, `TraceParams::ordered`). With it the
//!   per-ray cache saves nothing measurable: the cache only culls spheres that lie entirely
//!   behind the cached hit, and ordered traversal reaches those after the hit anyway. With
//!   `ordered = false` the cache cuts sphere tests by 26% and leaf tests by 33% on an
//!   unchanged frame (test `cache_hits_on_repeated_frames`), the paper's 27%. Under fast
//!   motion the cached leaf is often missed (surfels move more than their radius per
//!   frame); `TraceParams::cache_up` caches an ancestor instead (default 0 = the paper's leaf).
//!   With unordered traversal and an ancestor 8–12 levels up, the cache cuts the primary
//!   rays' ray–surfel tests by 12–33 % in the four sequences (paper 27 %), while front-to-back
//!   traversal alone cuts 38–59 % (README, "Caching"). CLI: `animate --cache-up N --unordered`.
//!
//! # Measured
//! Current figures and the commands that produce them are in the README ("Adams et al."):
//! `lodtrace bench SEQ --methods surfel:update=naive,...,surfel:update=refit`. In short, at
//! the paper's size (512×384, detail 1, 90 frames, stops 71–74), lazy-cache runs at
//! 2.06–2.25× the speed of a naive rebuild on three sequences and 1.84–1.91× on
//! `elastic-balls` (2.32× without shadow rays); the paper's update as written (`--exact-below
//! 0 --bound paper`) at 0.28–0.60× (stop 75, one run on a loaded host). Stop 37's figures, before
//! the subtree refits:
//! `animate --warm-pass` split a frame: the lazy update cost 33–41 % of the rebuild, but the rays cost 1.10–1.27×
//! as much in the lazy tree, which keeps the rest pose's topology (the paper's choice): on
//! `armadillo-ball` its sphere tests grow from 1.01× the rebuilt tree's in frame 0 to 2.38×
//! in frame 15 as the model collapses, while its spheres stay within 1.0–1.3× of the tightest
//! per node. The radius-ratio and MLS (1.8–2.8 iterations) targets hold.
//!
//! Layout: each collection's surfels are stored in the leaf order of a sphere tree over them
//! (`object`), so the lazy Eq. 1 work and the MLS neighbourhoods read nearby memory.

// `!(x > 0.0)` is used on purpose: it also rejects NaN. SoA loops index several arrays.
#![allow(clippy::neg_cmp_op_on_partial_ord, clippy::needless_range_loop, clippy::too_many_arguments)]

pub mod character;
pub mod displace;
pub mod knn;
pub mod miniball;
pub mod mls;
pub mod object;
pub mod ply;
pub mod sequences;
pub mod sim;
pub mod surfel;
pub mod top;
pub mod trace;
pub mod tree;

pub use displace::{DeformField, DeformedSurfel, SimNodes};
pub use mls::MlsParams;
pub use object::{ObjectParams, SurfelObject};
pub use sequences::{FrameNodes, Recording, Sequence, SequenceOptions};
pub use sim::{Body, BodyParams, CapStats, Collider, World};
pub use surfel::{Collection, SurfelModel, SurfelSoa};
pub use trace::{DeformCounters, DeformScene, DeformTracer, FrameStats, LevelRatio, SurfelHit, TraceParams, UpdateMode};

use std::path::PathBuf;

/// Errors of the deform module (typed; the CLI maps them to exit code 2).
#[derive(Debug, thiserror::Error)]
pub enum DeformError {
    #[error("{path}: {msg}")]
    Ply { path: PathBuf, msg: String },
    #[error("invalid surfel {index}: {msg}")]
    BadSurfel { index: usize, msg: String },
    #[error("duplicate points: surfels {a} and {b} have the same position (equal as f32 numbers)")]
    DuplicatePoint { a: usize, b: usize },
    #[error("too small to sample: {0}")]
    TooSmall(String),
    #[error("zero frames requested")]
    ZeroFrames,
    #[error("unknown sequence '{0}' (built-in: armadillo-ball, bend, heads, elastic-balls)")]
    UnknownSequence(String),
    #[error("frame data: {0}")]
    FrameMismatch(String),
    #[error("invalid deform input: {0}")]
    Invalid(String),
    #[error(transparent)]
    Load(#[from] crate::error::Error),
}
