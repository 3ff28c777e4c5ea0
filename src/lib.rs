//! bsdfit: fit BRDF and BTDF models to measured goniometric data with uncertainties.
//!
//! - [`dataset`]: the v1 CSV format, validation, channels.
//! - [`readers`]: every file format (v1 CSV, ALTA text, MERL binary) by content.
//! - [`model`]: the catalogue (one file per model, each with a WGSL twin in `shaders/`).
//! - [`loss`]: the benchmark's losses and χ².
//! - [`backend`]: the CPU reference and the GPU engine behind one trait.
//! - [`optim`]: compass search and Levenberg–Marquardt, all restarts in lockstep.
//! - [`fit`]: one fit and its report; [`uncertainty`]: parameter covariances.
//! - [`synth`]: synthetic data from known parameters.
//! - [`sweep`]: the benchmark sweep (resumable, shardable); [`plot`], [`render`],
//!   [`report`]: its angular plots, sphere renders and report.html.

pub mod backend;
pub mod bench;
pub mod dataset;
pub mod diagnose;
pub mod fit;
pub mod loss;
pub mod math;
pub mod model;
pub mod optim;
pub mod plot;
pub mod readers;
pub mod render;
pub mod report;
pub mod sweep;
pub mod synth;
pub mod uncertainty;
