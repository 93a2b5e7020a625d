//! `lodtrace verify`: cross-check an intersector against Embree.
use crate::baseline::accel::AccelKind;
use crate::error::{Error, Result};

#[derive(clap::Args, Debug, Clone)]
pub struct VerifyArgs {
    pub scene: String,
    #[arg(long, value_enum, default_value = "bvh")]
    pub accel: AccelKind,
    #[arg(long, default_value_t = 100_000)]
    pub rays: usize,
}

/// Returns the exit code: 0 agreement, 1 disagreement beyond tolerance.
pub fn run(_a: &VerifyArgs) -> Result<i32> {
    Err(Error::Usage("verify: not built yet".into()))
}
