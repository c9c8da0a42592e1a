//! Runs a loaded WCSPH scenario ([`runner`]): builds the simulation, steps the
//! pipeline, writes checkpoints, the summary and the resolved scenario, shows progress,
//! and times every stage ([`profile`]).

pub mod profile;
pub mod runner;
