//! What a user sees: angular plots, sphere renders and the sweep's report.
pub mod plot;
pub mod render;
pub mod report;
pub mod results;
