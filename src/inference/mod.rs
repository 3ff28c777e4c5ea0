//! From evaluations to answers: one fit and its report, parameter covariances, and the
//! statistics (χ² and F tails, information criteria) that judge a fit.
pub mod constraints;
pub mod covariance;
pub mod fit;
pub mod stats;
