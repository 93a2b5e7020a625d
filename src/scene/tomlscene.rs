//! TOML scene files: meshes, materials, transforms, instances, lights, camera.
use super::Scene;
use crate::error::{Error, Result};
use std::path::Path;

pub fn load(path: &Path) -> Result<Scene> {
    Err(Error::parse(path, "TOML scenes are not supported yet"))
}
