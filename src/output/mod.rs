//! What a user sees: angular plots, sphere renders and the sweep's report.
pub mod files;
pub mod plot;
pub mod render;
pub mod report;
pub mod results;

pub use files::{check_writable_dir, check_writable_file, write_atomic};
