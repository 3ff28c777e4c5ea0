//! What a user runs: the benchmark sweep, the discrepancy workflow, throughput benchmarks,
//! synthetic data, and a fit used elsewhere (eval, export).
pub mod bench;
pub mod checks;
pub mod collection;
pub mod diagnose;
pub mod export;
pub mod fit;
pub mod optical;
pub mod rgl;
pub mod scale;
pub mod sweep;
pub mod synth;
