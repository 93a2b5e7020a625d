//! `lodtrace demo`: the main job.
use crate::error::{Error, Result};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct DemoArgs {
    #[arg(long, default_value = "out")]
    pub out: PathBuf,
}

pub fn run(_a: &DemoArgs) -> Result<()> {
    Err(Error::Usage("demo: not built yet".into()))
}
