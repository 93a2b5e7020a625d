//! Side-by-side experiments: bench tables, JSON, plots, the demo report.
pub mod bench;
pub mod deform_bench;
pub mod demo;
pub mod plot;
pub mod run;
