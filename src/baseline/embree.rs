//! Embree 3.13.5 back-end (placeholder until the Embree work lands).
use super::accel::{Accel, Hit, Ray};
use crate::core::stats::Counters;
use crate::error::{Error, Result};
use crate::scene::Scene;

pub struct EmbreeAccel;

impl EmbreeAccel {
    pub fn build(_scene: &Scene) -> Result<Self> {
        Err(Error::Accel("Embree back-end not built yet".into()))
    }
}

impl Accel for EmbreeAccel {
    fn name(&self) -> &'static str {
        "embree"
    }
    fn intersect1(&self, _ray: &Ray, _c: &mut Counters) -> Option<Hit> {
        None
    }
    fn occluded1(&self, _ray: &Ray, _c: &mut Counters) -> bool {
        false
    }
    fn memory_bytes(&self) -> usize {
        0
    }
}
