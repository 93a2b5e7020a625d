//! `lodtrace render`.
use super::RenderArgs;
use crate::error::{Error, Result};
pub fn run(_a: &RenderArgs) -> Result<()> {
    Err(Error::Usage("render: not built yet".into()))
}
