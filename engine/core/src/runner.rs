//! The runner: sets the stages up, steps the pipeline to the end time inside `tracing`
//! spans, times every stage, shows progress, and writes `summary.json` and the
//! resolved scenario — also when the run stops early.

use crate::components::{Fluid, Ghost};
use crate::frame::write_fluid_frame;
use crate::scenario::Scenario;
use crate::sim::Sim;
use crate::stage::{SetupError, StepError};
use crate::world::count;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::path::PathBuf;
use std::time::{Duration, Instant};

/// How to run a scenario (the command line's options).
#[derive(Clone, Debug, Default)]
pub struct RunOptions {
    pub out_dir: PathBuf,
    /// Worker threads (default: rayon's, i.e. one per core).
    pub threads: Option<usize>,
    /// Show a progress bar on a terminal.
    pub progress: bool,
    /// Write a Chrome/Perfetto trace of the stage spans here.
    pub trace: Option<PathBuf>,
}

/// Time spent in one stage.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub calls: u64,
    pub seconds: f64,
}

/// The contents of `summary.json`.
#[derive(Clone, Debug, Default, Serialize)]
pub struct Summary {
    pub scenario: String,
    pub fluid_particles: usize,
    pub ghost_particles_mean: f64,
    pub steps: u64,
    pub simulated_time: f64,
    pub wall_seconds: f64,
    pub particle_steps_per_second: f64,
    pub threads: usize,
    pub stages: Vec<StageTime>,
    /// Named counters from the stages, e.g. `wall_reflections`.
    pub diagnostics: std::collections::BTreeMap<String, f64>,
    /// `completed`, or why the run stopped.
    pub status: String,
}

impl Summary {
    /// The per-stage time table printed by `--profile`.
    pub fn profile_table(&self) -> String {
        let total: f64 = self.stages.iter().map(|s| s.seconds).sum();
        let particle_steps = (self.fluid_particles as f64 * self.steps as f64).max(1.0);
        let mut out = format!(
            "{:<16} {:>8} {:>11} {:>11} {:>7} {:>13}\n",
            "stage", "calls", "total [s]", "mean [ms]", "share", "ns/particle-step"
        );
        for s in &self.stages {
            out += &format!(
                "{:<16} {:>8} {:>11.3} {:>11.4} {:>6.1}% {:>13.1}\n",
                s.stage,
                s.calls,
                s.seconds,
                1e3 * s.seconds / s.calls.max(1) as f64,
                100.0 * s.seconds / total.max(1e-300),
                1e9 * s.seconds / particle_steps
            );
        }
        out += &format!(
            "{:<16} {:>8} {:>11.3} {:>11} {:>7} {:>13.1}\n",
            "total",
            self.steps,
            total,
            "",
            "",
            1e9 * total / particle_steps
        );
        out
    }
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    #[error("{0}")]
    Setup(#[from] SetupError),
    #[error("step {step}, t = {time:.6} s, stage `{stage}`: {error}")]
    Step {
        step: u64,
        time: f64,
        stage: String,
        error: StepError,
        summary: Box<Summary>,
    },
    #[error("output {path}: {message}")]
    Output { path: String, message: String },
}

/// Runs a scenario to its end time. On an unstable step the run stops, writes the
/// offending frame (`unstable.vtp`) and the summary with the reason, finishes every
/// stage (flushing its files), and returns the error.
pub fn run(scenario: Scenario, opts: &RunOptions) -> Result<Summary, RunError> {
    run_keeping_state(scenario, opts).map(|(summary, _)| summary)
}

/// As [`run`], also returning the final state (for tests and studies).
pub fn run_keeping_state(
    scenario: Scenario,
    opts: &RunOptions,
) -> Result<(Summary, Sim), RunError> {
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(opts.threads.unwrap_or(0))
        .build()
        .map_err(|e| RunError::Output {
            path: "thread pool".into(),
            message: e.to_string(),
        })?;
    if let Some(path) = &opts.trace {
        // Fail before the run, with the path, rather than inside the trace writer.
        std::fs::File::create(path).map_err(|e| RunError::Output {
            path: path.display().to_string(),
            message: e.to_string(),
        })?;
    }
    // The subscriber is installed on the pool's thread, where the run happens.
    pool.install(|| match &opts.trace {
        Some(path) => {
            use tracing_subscriber::prelude::*;
            let (layer, _guard) = tracing_chrome::ChromeLayerBuilder::new()
                .file(path)
                .include_args(true)
                .build();
            let subscriber = tracing_subscriber::registry().with(layer);
            tracing::subscriber::with_default(subscriber, || run_in_pool(scenario, opts))
        }
        None => run_in_pool(scenario, opts),
    })
}

fn run_in_pool(mut scenario: Scenario, opts: &RunOptions) -> Result<(Summary, Sim), RunError> {
    let out = &opts.out_dir;
    let io_err = |e: std::io::Error| RunError::Output {
        path: out.display().to_string(),
        message: e.to_string(),
    };
    std::fs::create_dir_all(out).map_err(io_err)?;
    // A stale frame from an earlier failed run in this folder would mislead.
    let _ = std::fs::remove_file(out.join("unstable.vtp"));
    crate::output::atomic::write_atomic(
        &out.join("scenario.resolved.ron"),
        scenario.resolved_ron().as_bytes(),
    )
    .map_err(io_err)?;

    let mut sim = scenario.build_sim(out.clone());
    let mut pipeline = std::mem::take(&mut scenario.spec.pipeline);
    for entry in &mut pipeline {
        let _span = tracing::info_span!("setup", stage = entry.name.as_str()).entered();
        entry.stage.setup(&mut sim)?;
    }
    let mut summary = Summary {
        scenario: sim.name.clone(),
        fluid_particles: count::<Fluid>(&sim.world),
        threads: rayon::current_num_threads(),
        stages: pipeline
            .iter()
            .map(|e| StageTime {
                stage: e.name.clone(),
                ..StageTime::default()
            })
            .collect(),
        status: "running".into(),
        ..Summary::default()
    };
    let progress = progress_bar(opts.progress, sim.clock.end_time);
    let start = Instant::now();
    let mut ghost_sum = 0.0;
    let mut failure = None;
    'steps: while sim.clock.time < sim.clock.end_time * (1.0 - 1e-12) {
        let step = sim.clock.step;
        let _span = tracing::info_span!("step", step).entered();
        for (entry, time) in pipeline.iter_mut().zip(summary.stages.iter_mut()) {
            if !step.is_multiple_of(entry.every as u64) {
                continue;
            }
            let t0 = Instant::now();
            let result = {
                let _span = tracing::info_span!("stage", name = entry.name.as_str()).entered();
                entry.stage.run(&mut sim)
            };
            time.calls += 1;
            time.seconds += t0.elapsed().as_secs_f64();
            if let Err(error) = result {
                failure = Some((entry.name.clone(), step, error));
                break 'steps;
            }
        }
        if sim.clock.step == step {
            failure = Some((
                "runner".into(),
                step,
                StepError::Internal(
                    "no stage advanced the clock: add Integrate() to the pipeline".into(),
                ),
            ));
            break;
        }
        ghost_sum += count::<Ghost>(&sim.world) as f64;
        if step.is_multiple_of(20) {
            update_progress(&progress, &sim, summary.fluid_particles, start.elapsed());
        }
    }
    summary.steps = sim.clock.step;
    summary.simulated_time = sim.clock.time;
    summary.wall_seconds = start.elapsed().as_secs_f64();
    summary.ghost_particles_mean = ghost_sum / (summary.steps.max(1) as f64);
    summary.particle_steps_per_second =
        summary.fluid_particles as f64 * summary.steps as f64 / summary.wall_seconds.max(1e-9);
    progress.finish_and_clear();
    summary.diagnostics = sim.diagnostics.clone();

    if let Some((_, step, error)) = &failure {
        summary.status = format!(
            "stopped at step {step}, t = {:.6} s: {error}",
            sim.clock.time
        );
        // Keep the offending state for inspection; a failure here must not hide the first.
        let _ = write_fluid_frame(&sim, &out.join("unstable.vtp"));
    } else {
        summary.status = "completed".into();
    }
    let mut finish_error = None;
    for entry in &mut pipeline {
        if let Err(e) = entry.stage.finish(&mut sim) {
            finish_error.get_or_insert((entry.name.clone(), e));
        }
    }
    let json = serde_json::to_string_pretty(&summary).unwrap_or_default();
    crate::output::atomic::write_atomic(&out.join("summary.json"), json.as_bytes())
        .map_err(io_err)?;
    match failure.or(finish_error.map(|(stage, e)| (stage, sim.clock.step, e))) {
        Some((stage, step, error)) => Err(RunError::Step {
            step,
            time: sim.clock.time,
            stage,
            error,
            summary: Box::new(summary),
        }),
        None => Ok((summary, sim)),
    }
}

fn progress_bar(show: bool, end_time: f64) -> ProgressBar {
    if !show {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::with_draw_target(
        Some((end_time * 1e4).ceil() as u64),
        ProgressDrawTarget::stderr(),
    );
    if let Ok(style) = ProgressStyle::with_template("{bar:40} t = {msg} ETA {eta}") {
        bar.set_style(style);
    }
    bar
}

fn update_progress(bar: &ProgressBar, sim: &Sim, particles: usize, elapsed: Duration) {
    bar.set_position((sim.clock.time * 1e4) as u64);
    let rate = particles as f64 * sim.clock.step as f64 / elapsed.as_secs_f64().max(1e-9);
    bar.set_message(format!(
        "{:.3} / {:.3} s, step {}, dt {:.2e} s, {:.2e} particle-steps/s",
        sim.clock.time, sim.clock.end_time, sim.clock.step, sim.clock.dt, rate
    ));
}
