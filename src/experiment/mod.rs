//! Side-by-side experiments: bench tables, JSON, plots, the demo report.
pub mod bench;
pub mod deform_bench;
pub mod demo;
pub mod plot;
pub mod run;

/// What a table cell shows where a figure does not exist (no partner row, not counted, not
/// measured): one en dash in every table (until stop 81 some tables used "-", others "–").
pub const NA: &str = "–";
