//! Test support and an example plugin stage (see `plugin`).

pub mod plugin;
pub mod stability;
pub mod support;
