//! Core of the WCSPH engine: the particle world and its components, the stage trait and
//! registry, the scenario loader, the runner with its profiler, and the output writers.
//! The standard stages live in the `sph-stages` crate; the `engine` binary joins them.

pub mod checkpoint;
pub mod components;
pub mod contract;
pub mod frame;
pub mod kernel;
pub mod kinematics;
pub mod linear_sloshing;
pub mod motion;
pub mod output;
pub mod overrides;
pub mod pair;
pub mod parallel;
pub mod piston;
pub mod profile;
pub mod registry;
pub mod runner;
pub mod scenario;
pub mod series;
pub mod sim;
pub mod stage;
pub mod study;
pub mod sweep;
pub mod vocab;
pub mod walls;
pub mod waves;
pub mod world;

pub use registry::{ParamError, StageRegistry};
pub use scenario::{LoadError, Scenario};
pub use sim::Sim;
pub use stage::{SetupError, Stage, StateError, StepError};
