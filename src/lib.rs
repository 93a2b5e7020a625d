//! # lodtrace
//!
//! A research ray tracer for three papers on multi-resolution ray tracing, measured against
//! conventional baselines and verified against Embree:
//!
//! 1. Wand & Straßer 2003, *Multi-Resolution Point-Sample Raytracing* (`multires`),
//! 2. Adams et al. 2005, *Efficient Raytracing of Deforming Point-Sampled Surfaces* (`deform`),
//! 3. Papaioannou et al., *Multiresolution models accelerate ray tracing* (`lod`).
//!
//! Data flows one way: [`scene`] (SoA meshes, materials, lights, camera, instancing) →
//! acceleration structure ([`baseline::accel`]: Embree or obvhs' CWBVH) → integrator
//! ([`baseline`] Whitted and distributed) → [`film`] (PNG, EXR AOVs, metrics) → outputs and
//! side-by-side comparisons ([`experiment`]). Counters ([`core::stats`]) run throughout.

// `!(a < b)` is written on purpose throughout: it is also true when either side is NaN, which
// is how degenerate inputs are rejected (a NaN distance or radius must fail a test, not pass).
#![allow(clippy::neg_cmp_op_on_partial_ord)]

pub mod baseline;
pub mod cli;
pub mod core;
pub mod deform;
pub mod error;
pub mod experiment;
pub mod film;
pub mod lod;
pub mod multires;
pub mod scene;

pub use error::{Error, Result};
