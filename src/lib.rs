//! bsdfit: fit BRDF and BTDF models to measured goniometric data with uncertainties.
//!
//! The modules follow the pipeline, in order:
//! - [`data`]: measurements in (the v1 CSV format, validation, channels).
//! - [`bsdf`]: the model catalogue, driven by declarations (one file per model, each the
//!   twin of a WGSL file in `shaders/bsdf/`), the spec parser and the compiled [`bsdf::Model`].
//! - [`engine`]: the losses, and the CPU reference and the GPU engine behind one trait.
//! - [`optim`]: compass search and Levenberg–Marquardt, all restarts in lockstep; they know
//!   nothing of backends.
//! - [`inference`]: one fit and its report, covariances, χ²/F tails and information criteria.
//! - [`workflows`]: sweep, diagnose, bench and synth.
//! - [`output`]: angular plots, sphere renders and the sweep's report.
//! - [`cli`]: every command's options (shared groups flattened into each command).
//!
//! [`math`] holds the geometry and special functions every stage uses; [`choice`] the
//! word tables of options whose value is one of a few words; [`text`] the words of
//! messages (counts with their nouns).

pub mod bsdf;
pub mod choice;
pub mod cli;
pub mod data;
pub mod engine;
pub mod inference;
pub mod math;
pub mod optim;
pub mod output;
pub mod text;
pub mod workflows;
