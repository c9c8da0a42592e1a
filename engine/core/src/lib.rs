//! The plugin-facing core of the WCSPH engine: the particle world and its components,
//! the stage trait and its contracts, the stage registry, the simulation state
//! ([`Sim`]), checkpoints, the pair layer and kernels, the scene's motion (walls,
//! pistons, kinematics), time-series CSV writing and the errors stages return. A
//! plugin (a crate of stages) depends on this crate only.
//!
//! The rest lives in crates named for their job: `sph-output` (ParaView frames, PNG
//! snapshots and plots), `sph-scenario` (the scenario loader and `--set` overrides),
//! `sph-run` (the runner and its profiler), `sph-study` (studies, sweeps, linear
//! sloshing theory, wave analysis); the standard stages are in `sph-stages`, and the
//! `engine` binary joins them.

pub mod atomic;
pub mod checkpoint;
pub mod components;
pub mod contract;
pub mod dim;
pub mod extraction;
pub mod extremes;
pub mod kernel;
pub mod kinematics;
pub mod motion;
pub mod pair;
pub mod piston;
pub mod registry;
pub mod series;
pub mod sim;
pub mod stage;
pub mod terms;
pub mod units;
pub mod vocab;
pub mod walls;
pub mod world;

pub use registry::{ParamError, StageRegistry};
pub use sim::Sim;
pub use stage::{SetupError, Stage, StateError, StepError};
