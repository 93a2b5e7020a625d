//! `lodtrace bench`: several methods on the same scenes in one process.
use crate::error::{Error, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct BenchArgs {
    /// Scenes (built-in names or files).
    #[arg(required = true)]
    pub scenes: Vec<String>,
    /// Comma-separated method specs, e.g. `whitted:embree,whitted:bvh,distributed:embree:spp=16`.
    #[arg(long, required = true)]
    pub methods: String,
    /// Reference spec for the error columns, e.g. `distributed:embree:spp=256`.
    #[arg(long)]
    pub reference: Option<String>,
    #[arg(long)]
    pub out: Option<PathBuf>,
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

pub fn run(_a: &BenchArgs) -> Result<()> {
    Err(Error::Usage("bench: not built yet".into()))
}
