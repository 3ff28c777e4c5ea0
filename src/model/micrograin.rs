//! Micrograin layer shared math (placeholder).
