//! What a user runs: the benchmark sweep, the discrepancy workflow, throughput benchmarks
//! and synthetic data.
pub mod bench;
pub mod diagnose;
pub mod sweep;
pub mod synth;
