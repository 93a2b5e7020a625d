//! # lodtrace
//!
//! A research ray tracer for three papers on multi-resolution ray tracing, measured against
//! conventional baselines and verified against Embree:
//!
//! 1. Wand & Straßer 2003, *Multi-Resolution Point-Sample Raytracing* (`multires`),
//! 2. Adams et al. 2005, *Ray Tracing Dynamic Scenes with Point-Sampled Surfaces* (`deform`),
//! 3. Papaioannou et al., *Multiresolution models accelerate ray tracing* (`lod`).
//!
//! Data flows one way: [`scene`] (SoA meshes, materials, lights, camera, instancing) →
//! acceleration structure ([`baseline::accel`]: Embree or obvhs' CWBVH) → integrator
//! ([`baseline`] Whitted and distributed) → [`film`] (PNG, EXR AOVs, metrics) → outputs and
//! side-by-side comparisons ([`experiment`]). Counters ([`core::stats`]) run throughout.

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
