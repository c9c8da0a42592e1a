//! An example plugin: a stage defined in a crate of its own, outside `engine/` and
//! `stages/`, the worked example of how to add a stage. `src/main.rs` is the `engine`
//! command with it registered: `cargo run --release -p max-speed -- plugins/max-speed/max_speed.ron`.
//!
//! The library uses `sph-core` only, the plugin-facing crate (a stage that plots its
//! series adds `sph-output` for `SeriesPlot`); `sph-stages` and `engine` are for the
//! binary.
//!
//! `MaxSpeed` measures the largest fluid speed each step, keeps it in the run's
//! diagnostics (`summary.json`) and writes it to `max_speed.csv` every `interval`
//! seconds of simulated time. A scenario uses it like any standard stage:
//!
//! ```ron
//! pipeline: [
//!     // ... the standard stages ...
//!     Integrate(),
//!     MaxSpeed(interval: 0.01),
//! ],
//! ```
//!
//! # Adding a stage, step by step
//!
//! 1. **Parameters.** Write a struct deriving `Serialize` and `Deserialize` with
//!    `#[serde(default, deny_unknown_fields)]` and a `Default` impl: omitted fields
//!    take the documented defaults, and a misspelt field is refused with
//!    `file:line:column` and the list of accepted fields. Document each field with its
//!    unit and default; the run's `scenario.resolved.ron` records the values used.
//!    (`every: N`, to run a stage every N steps, is handled by the runner for every
//!    stage; do not declare it.)
//! 2. **Validation.** The constructor passed to [`StageRegistry::register_checked`]
//!    receives the parsed parameters and returns the stage, or a [`ParamError`] for an
//!    out-of-range value, naming the field and what is accepted
//!    (`ParamError::new("interval", -1, "seconds >= 0")`, shown as "field `interval` =
//!    -1 is out of range; accepted: seconds >= 0"). The loader adds the file, line and
//!    column.
//! 3. **The stage.** Implement [`Stage`]:
//!    - [`Stage::name`]: the registered snake_case name (used in spans, the profile
//!      table and errors);
//!    - [`Stage::setup`] (once, in pipeline order): create output files, insert the
//!      resources and per-particle components the stage owns, and check that what it
//!      needs from earlier stages is there, failing with a [`SetupError`] that says
//!      how to fix the scenario;
//!    - [`Stage::run`] (every step): read and write the [`Sim`] — particle columns
//!      through [`Particles`], the clock, constants, resources and diagnostics;
//!    - [`Stage::finish`] (after the last step, also after an unstable stop): flush
//!      files, draw plots;
//!    - [`Stage::access`]: what the stage reads and writes, as typed quantities
//!      ([`sph_core::contract`]): particle components, the shared vocabulary
//!      ([`sph_core::vocab`]: neighbour lists, half-step state, wall poses, ...) or
//!      the clock. The loader refuses a scenario where two stages write one quantity,
//!      or a stage reads one that no earlier stage writes (nor the initial state
//!      holds), naming the stage's line. Only a stage that declares the clock may
//!      change it. A stage that declares nothing is trusted, as before;
//!    - [`Stage::save_state`] and [`Stage::load_state`] (checkpoints, `engine
//!      resume`): a stage that keeps anything between steps (counters, the next
//!      sample time, per-particle columns it owns) encodes it with
//!      [`sph_core::checkpoint::Enc`] and flushes its files; a stateless stage keeps
//!      the defaults. Open CSV series with [`SeriesWriter::open`] so a resumed run
//!      continues them. Without these a resumed run still runs, but not bit for bit.
//! 4. **Registration.** Give the crate a `pub fn register(registry: &mut StageRegistry)`
//!    (as [`register`] below). A program that wants the stage builds its registry with
//!    `sph_stages::standard_registry()` and then calls it; a command-line binary is
//!    `engine::main_with(registry)`:
//!
//!    ```no_run
//!    fn main() -> std::process::ExitCode {
//!        let mut registry = sph_stages::standard_registry();
//!        max_speed::register(&mut registry);
//!        engine::main_with(registry)
//!    }
//!    ```
//!
//!    The scenario names the stage in CamelCase (`MaxSpeed(...)`); a registry without
//!    the plugin refuses the file with "unknown stage `MaxSpeed`".
//!
//! `tests/tests/plugin.rs` runs this stage on `plugins/max-speed/max_speed.ron`, and the
//! binary on it.

use serde::{Deserialize, Serialize};
use sph_core::checkpoint::{Dec, Enc};
use sph_core::components::Velocity;
use sph_core::contract::Access;
use sph_core::series::SeriesWriter;
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, Stage, StepError};
use sph_core::world::Particles;
use sph_core::{ParamError, StageRegistry};

/// The registered name: written `MaxSpeed(...)` in scenario files.
pub const NAME: &str = "max_speed";

/// The output file, in the run's output folder.
pub const CSV: &str = "max_speed.csv";

/// Parameters of `MaxSpeed(...)`.
#[derive(Debug, Clone, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Params {
    /// Sampling interval of `max_speed.csv` [s]; 0 writes every step. Default 0.01.
    pub interval: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self { interval: 0.01 }
    }
}

/// Registers `MaxSpeed` in `registry`.
pub fn register(registry: &mut StageRegistry) {
    registry.register_checked(
        NAME,
        "largest fluid speed to max_speed.csv and the summary's diagnostics",
        |p: Params| {
            if !(p.interval >= 0.0 && p.interval.is_finite()) {
                return Err(ParamError::new("interval", p.interval, "seconds >= 0"));
            }
            Ok(MaxSpeed {
                params: p,
                next: 0.0,
                peak: 0.0,
                out: None,
            })
        },
    );
}

/// The stage. Place it after `Integrate` to measure the velocities of the step just
/// taken.
pub struct MaxSpeed {
    params: Params,
    /// Simulated time of the next CSV row [s].
    next: f64,
    /// Largest speed seen so far [m/s].
    peak: f64,
    out: Option<SeriesWriter>,
}

/// The largest speed |v| over the fluid particles [m/s]; 0 without fluid.
pub fn max_fluid_speed(sim: &Sim) -> Result<f64, StepError> {
    let Some(particles) = Particles::of(&sim.world) else {
        return Ok(0.0);
    };
    let v = particles.fluid::<Velocity>()?;
    // A serial fold: exact and independent of the thread count. (A hot stage would use
    // rayon's `par_iter` on the slice; `max` is order-independent so it stays exact.)
    // NaN-propagating (not f64::max, which drops a NaN): the caller's finiteness check
    // must see a NaN velocity.
    Ok(v.iter().map(|v| v.0.length()).fold(0.0, |m: f64, s| {
        if m.is_nan() || s.is_nan() {
            f64::NAN
        } else {
            m.max(s)
        }
    }))
}

impl Stage for MaxSpeed {
    fn name(&self) -> &'static str {
        NAME
    }

    fn setup(&mut self, sim: &mut Sim) -> Result<(), SetupError> {
        let columns = vec!["max_speed".to_string()];
        // `open_sampled`, not `create`: a resumed run continues the file.
        // It also refuses an interval giving an absurd number of rows.
        let out =
            SeriesWriter::open_sampled(sim, &sim.out_dir.join(CSV), columns, self.params.interval)
                .map_err(|e| SetupError::new(NAME, e.to_string()))?;
        self.out = Some(out);
        Ok(())
    }

    fn run(&mut self, sim: &mut Sim) -> Result<(), StepError> {
        let speed = max_fluid_speed(sim)?;
        if !speed.is_finite() {
            return Err(StepError::Unstable {
                what: format!("fluid speed is {speed}"),
                particle: None,
                position: None,
            });
        }
        self.peak = self.peak.max(speed);
        // This step's value and the run's peak; both end up in summary.json.
        sim.diagnostics.insert("max_speed".into(), speed);
        sim.diagnostics.insert("max_speed_peak".into(), self.peak);
        if sim.clock.time + 1e-12 < self.next {
            return Ok(());
        }
        self.next = sim.clock.time + self.params.interval;
        if let Some(out) = &mut self.out {
            out.push(sim.clock.time, vec![speed])?;
        }
        Ok(())
    }

    /// Checkpoint: flush the CSV (its rows up to now must be on disk) and keep what the
    /// next steps depend on. Restored by `load_state` on `engine resume`.
    fn save_state(&mut self, _sim: &Sim) -> Result<Vec<u8>, StepError> {
        if let Some(out) = &mut self.out {
            out.flush()?;
        }
        let mut e = Enc::default();
        e.f64(self.next);
        e.f64(self.peak);
        Ok(e.into_bytes())
    }

    fn load_state(&mut self, _sim: &mut Sim, state: &[u8]) -> Result<(), sph_core::StateError> {
        let mut d = Dec::new(state);
        self.next = d.f64()?;
        self.peak = d.f64()?;
        d.end()
    }

    fn finish(&mut self, _sim: &mut Sim) -> Result<(), StepError> {
        match &mut self.out {
            Some(out) => out.flush(),
            None => Ok(()),
        }
    }

    /// Reads the fluid velocities (which the initial state holds and `Integrate`
    /// writes); writes nothing another stage reads.
    fn access(&self) -> Access {
        Access::new().reads::<Velocity>()
    }
}
