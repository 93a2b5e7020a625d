//! Conventional tracers (the baselines the papers compare against): the intersection
//! back-ends (Embree, obvhs CWBVH), shading, and the Whitted and adaptive distributed
//! integrators of Wand & Straßer §6.
pub mod accel;
pub mod bvh;
#[cfg(feature = "embree")]
pub mod embree;
pub mod render;
pub mod shade;
pub mod tri;
#[cfg(feature = "embree")]
pub mod verify;
