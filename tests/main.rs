//! The integration tests, one binary (`cargo test --release --test suite MODULE::`): every
//! file here is a module, so the library is linked once instead of once per file.

mod common;

mod cli;
mod crosscheck;
mod deform;
mod film;
mod lod;
mod multires;
mod render;
mod scenes;
