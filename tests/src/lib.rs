//! Test support: scenario loading and runs, CSV reading, stability checks.

pub mod stability;
pub mod support;
