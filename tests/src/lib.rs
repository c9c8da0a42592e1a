//! Test support and an example plugin stage (see `plugin`).
