//! From evaluations to answers: one fit and its report (with the user's constraints),
//! parameter covariances, the statistics (χ² and F tails, information criteria) that judge
//! a fit, bootstrap-calibrated extension tests, Monte Carlo parameter distributions, and a saved fit read back with its model uncertainty propagated to new
//! geometries.
pub mod bootstrap;
pub mod constraints;
pub mod covariance;
pub mod fit;
pub mod knots;
pub mod mc;
pub mod mc_summary;
pub mod saved;
pub mod stats;
