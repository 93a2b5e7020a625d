//! `lodtrace compare A B [--diff FILE]`.
use crate::error::{Error, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct CompareArgs {
    pub a: PathBuf,
    pub b: PathBuf,
    #[arg(long)]
    pub diff: Option<PathBuf>,
}

pub fn run(_a: &CompareArgs) -> Result<i32> {
    Err(Error::Usage("compare: not built yet".into()))
}
