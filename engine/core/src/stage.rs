//! The stage trait: one step of the pipeline (neighbour grid, density, EOS, forces, ...).

use crate::dim::Vector;
use crate::sim::Sim;

pub use crate::checkpoint::StateError;

/// A pipeline stage. The runner calls [`Stage::setup`] once for every stage in
/// pipeline order before the first step, then [`Stage::run`] for every stage in order
/// each step (inside a `tracing` span named after the stage), then [`Stage::finish`].
pub trait Stage: Send {
    /// The registered name (snake_case), used in spans, the profile table and errors.
    fn name(&self) -> &'static str;

    /// Adds the components and resources this stage owns, and checks that what it needs
    /// from earlier stages is there. Runs once, in pipeline order.
    fn setup(&mut self, _sim: &mut Sim) -> Result<(), SetupError> {
        Ok(())
    }

    /// Advances this stage's part of one time step.
    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError>;

    /// After the last step (also after an unstable stop): flush files, draw plots.
    fn finish(&mut self, _sim: &mut Sim) -> Result<(), StepError> {
        Ok(())
    }

    /// What the stage reads and writes ([`crate::contract`]): the scenario loader
    /// refuses a pipeline with two writers of one quantity, or a reader with no writer
    /// before it, and only a stage that declares the clock may change it. Called once,
    /// when the scenario loads. The default declares nothing: the stage is trusted, as
    /// before contracts, but may not change the clock.
    fn access(&self) -> crate::contract::Access {
        crate::contract::Access::default()
    }

    /// Whether a run may checkpoint (and resume) between two calls of this stage when
    /// the scenario runs it every N > 1 steps: true when all the stage leaves for later
    /// steps is in the world's columns or its [`Stage::save_state`] (an in-place
    /// filter). The default, false, puts checkpoints only on steps where the stage runs
    /// next, so that what it builds for the steps after it (lists, caches) is rebuilt
    /// on the first step after a resume.
    fn resumes_between_runs(&self) -> bool {
        false
    }

    /// The stage's private state for a checkpoint (counters, next sample time,
    /// per-particle columns it owns), encoded with [`crate::checkpoint::Enc`]. Stages
    /// that write files flush them here, so the files hold every row up to the
    /// checkpoint. Stateless stages keep the default (nothing). Called between steps.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        Ok(Vec::new())
    }

    /// Restores what [`Stage::save_state`] wrote, after [`Stage::setup`] on a run that
    /// resumes from a checkpoint (the particles and the clock are already restored).
    fn load_state(&mut self, _sim: &mut Sim, _state: &[u8]) -> Result<(), StateError> {
        Ok(())
    }
}

/// A stage cannot start: the message says what is missing and how to fix the scenario.
#[derive(Debug, thiserror::Error)]
#[error("stage `{stage}`: {message}")]
pub struct SetupError {
    pub stage: &'static str,
    pub message: String,
}

impl SetupError {
    pub fn new(stage: &'static str, message: impl Into<String>) -> Self {
        Self {
            stage,
            message: message.into(),
        }
    }
}

/// Why a step could not be completed.
#[derive(Debug, thiserror::Error)]
pub enum StepError {
    /// The simulation went unstable: non-finite values, a particle leaving the domain,
    /// density out of bounds, or the time step collapsing.
    #[error("{what}{}", particle_text(.particle, .position))]
    Unstable {
        what: String,
        particle: Option<u32>,
        position: Option<Vector>,
    },
    /// Writing an output failed.
    #[error("output {path}: {message}")]
    Output { path: String, message: String },
    /// The particles lack a component a stage reads: the stage that provides it is not
    /// in the pipeline (or comes after).
    #[error("particles have no `{0}` component: the stage that provides it is missing from the pipeline")]
    MissingComponent(&'static str),
    /// A step ended without any stage advancing the clock.
    #[error("no stage advanced the clock: add Integrate() to the pipeline")]
    ClockStalled,
    /// A bug or an inconsistent pipeline.
    #[error("{0}")]
    Internal(String),
}

fn particle_text(particle: &Option<u32>, position: &Option<Vector>) -> String {
    match (particle, position) {
        #[cfg(not(feature = "dim3"))]
        (Some(i), Some(x)) => format!(" (particle {i} at x = {:.4} m, y = {:.4} m)", x.x, x.y),
        #[cfg(feature = "dim3")]
        (Some(i), Some(x)) => format!(
            " (particle {i} at x = {:.4} m, y = {:.4} m, z = {:.4} m)",
            x.x, x.y, x.z
        ),
        (Some(i), None) => format!(" (particle {i})"),
        _ => String::new(),
    }
}

impl StepError {
    pub fn output(path: &std::path::Path, err: impl std::fmt::Display) -> Self {
        StepError::Output {
            path: path.display().to_string(),
            message: err.to_string(),
        }
    }
}
