//! Plots (PNG) for bench results.
