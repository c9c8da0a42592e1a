//! Time integration: the WCSPH predictor-corrector and the DFSPH advance.

pub mod advance;
pub mod integrate;
