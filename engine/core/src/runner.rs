//! The runner: sets the stages up, steps the pipeline to the end time inside `tracing`
//! spans, times every stage, shows progress, and writes `summary.json` and the
//! resolved scenario — also when the run stops early.

use crate::checkpoint::{Checkpoint, Dec, Origin, Resuming};
use crate::components::{Fluid, Ghost};
use crate::frame::write_fluid_frame;
use crate::scenario::PipelineEntry;
use crate::scenario::Scenario;
use crate::sim::Sim;
use crate::stage::{SetupError, StepError};
use crate::world::count;
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
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
    /// Write a checkpoint about every this many seconds of simulated time.
    pub checkpoint_every: Option<f64>,
    /// Stop once the simulated time reaches this [s], writing a checkpoint.
    pub stop_at: Option<f64>,
    /// Continue from this checkpoint ([`crate::checkpoint::read_latest`]); the scenario
    /// must be the one it was written for.
    pub resume: Option<Checkpoint>,
    /// Set (e.g. by a Ctrl-C handler) to stop the run with a checkpoint.
    pub interrupt: Option<Arc<AtomicBool>>,
    /// The scenario file and overrides, recorded in checkpoints for `engine resume`.
    pub origin: Origin,
}

impl RunOptions {
    /// A batch run into `out_dir` on `threads` threads: no progress bar, no trace, no
    /// checkpoints (sweeps, studies, benchmarks, tests).
    pub fn quiet(out_dir: impl Into<PathBuf>, threads: usize) -> Self {
        Self {
            out_dir: out_dir.into(),
            threads: Some(threads),
            ..Self::default()
        }
    }
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
    /// A run option out of range (`--checkpoint-every`, `--stop-at`).
    #[error("{0}")]
    Options(String),
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
    check_options(opts)?;
    prepare_out_dir(out)?;
    // A stale frame from an earlier failed run in this folder would mislead.
    let _ = std::fs::remove_file(out.join("unstable.vtp"));
    let resolved = scenario.resolved_ron();
    let fingerprint = crate::checkpoint::fingerprint(&resolved);
    if let Some(c) = &opts.resume {
        if c.fingerprint != fingerprint {
            return Err(RunError::Output {
                path: c.file.display().to_string(),
                message: "the checkpoint was written for another scenario (the scenario file, its overrides or the engine's defaults changed since); rerun from the start".into(),
            });
        }
    }
    crate::output::atomic::write_atomic(&out.join("scenario.resolved.ron"), resolved.as_bytes())
        .map_err(io_err)?;

    let mut sim = scenario.build_sim(out.clone());
    let mut pipeline = std::mem::take(&mut scenario.spec.pipeline);
    if let Some(c) = &opts.resume {
        sim.resources.insert(Resuming { time: c.time });
    }
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
    let mut ghost_sum = 0.0;
    if let Some(c) = &opts.resume {
        restore(c, &mut sim, &mut pipeline, &mut summary, &mut ghost_sum).map_err(|message| {
            RunError::Output {
                path: c.file.display().to_string(),
                message,
            }
        })?;
    }
    let start_step = sim.clock.step;
    // Checkpoints fall on steps where every stage runs next, so the stages' outputs
    // (neighbour lists, ...) are all rebuilt on the first step after a resume.
    let period = pipeline
        .iter()
        .fold(1u64, |l, e| lcm(l, e.every.max(1) as u64));
    let mut next_checkpoint = opts
        .checkpoint_every
        .map(|every| every * ((sim.clock.time / every).floor() + 1.0));
    let progress = progress_bar(opts.progress, sim.clock.end_time);
    let start = Instant::now();
    let mut failure = None;
    let mut paused = None;
    'steps: while sim.clock.time < sim.clock.end_time * (1.0 - 1e-12) {
        let step = sim.clock.step;
        let _span = tracing::info_span!("step", step).entered();
        for (entry, time) in pipeline.iter_mut().zip(summary.stages.iter_mut()) {
            if !step.is_multiple_of(entry.every as u64) {
                continue;
            }
            let t0 = Instant::now();
            let clock = clock_bits(&sim);
            let result = {
                let _span = tracing::info_span!("stage", name = entry.name.as_str()).entered();
                entry.stage.run(&mut sim)
            };
            time.calls += 1;
            time.seconds += t0.elapsed().as_secs_f64();
            // Only the stage that declares the clock among its writes may change it.
            let result = result.and_then(|()| {
                if clock_bits(&sim) == clock || entry.access().writes_clock() {
                    Ok(())
                } else {
                    Err(StepError::Internal(format!(
                        "stage `{}` changed the clock without declaring it (Stage::access); only the stage that advances the clock may",
                        entry.name
                    )))
                }
            });
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
            let steps = sim.clock.step - start_step;
            update_progress(
                &progress,
                &sim,
                summary.fluid_particles * steps as usize,
                start.elapsed(),
            );
        }
        let done = sim.clock.time >= sim.clock.end_time * (1.0 - 1e-12);
        if done || !sim.clock.step.is_multiple_of(period) {
            continue;
        }
        let interrupted = opts
            .interrupt
            .as_ref()
            .is_some_and(|f| f.load(Ordering::Relaxed));
        let stop = opts.stop_at.is_some_and(|t| sim.clock.time >= t);
        let due = next_checkpoint.is_some_and(|t| sim.clock.time >= t * (1.0 - 1e-12));
        if !(interrupted || stop || due) {
            continue;
        }
        summary.steps = sim.clock.step;
        if let Err(error) = checkpoint(&sim, &mut pipeline, &summary, ghost_sum, fingerprint, opts)
        {
            failure = Some(("checkpoint".into(), sim.clock.step, error));
            break;
        }
        if let (Some(every), Some(next)) = (opts.checkpoint_every, &mut next_checkpoint) {
            *next = every * ((sim.clock.time / every).floor() + 1.0);
        }
        if interrupted || stop {
            paused = Some(if interrupted {
                "interrupted"
            } else {
                "paused (--stop-at)"
            });
            break;
        }
    }
    summary.steps = sim.clock.step;
    summary.simulated_time = sim.clock.time;
    summary.wall_seconds = start.elapsed().as_secs_f64();
    summary.ghost_particles_mean = ghost_sum / (summary.steps.max(1) as f64);
    summary.particle_steps_per_second = summary.fluid_particles as f64
        * (summary.steps - start_step) as f64
        / summary.wall_seconds.max(1e-9);
    progress.finish_and_clear();
    summary.diagnostics = sim.diagnostics.clone();

    if let Some((_, step, error)) = &failure {
        summary.status = format!(
            "stopped at step {step}, t = {:.6} s: {error}",
            sim.clock.time
        );
        // Keep the offending state for inspection; a failure here must not hide the first.
        let _ = write_fluid_frame(&sim, &out.join("unstable.vtp"));
    } else if let Some(how) = paused {
        summary.status = format!(
            "{how} at step {}, t = {:.6} s, with a checkpoint: continue with `engine resume {}`",
            sim.clock.step,
            sim.clock.time,
            out.display()
        );
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

/// The clock's time, step and dt, exactly (the end time is the run's, not the clock's).
fn clock_bits(sim: &Sim) -> (u64, u64, u64) {
    let c = &sim.clock;
    (c.time.to_bits(), c.step, c.dt.to_bits())
}

/// Refuses checkpoint options that make no sense, before anything is written.
fn check_options(opts: &RunOptions) -> Result<(), RunError> {
    let bad = |name: &str, v: f64| {
        RunError::Options(format!("{name} {v} is out of range; accepted: seconds > 0"))
    };
    if let Some(t) = opts
        .checkpoint_every
        .filter(|t| !(*t > 0.0 && t.is_finite()))
    {
        return Err(bad("--checkpoint-every", t));
    }
    if let Some(t) = opts.stop_at.filter(|t| !(*t > 0.0 && t.is_finite())) {
        return Err(bad("--stop-at", t));
    }
    Ok(())
}

/// Creates the output folder and checks, by writing and removing a small file, that
/// outputs can be written there: an unwritable folder or a full disk is reported
/// before the run rather than when the first output is due.
pub fn prepare_out_dir(out: &Path) -> Result<(), RunError> {
    let err = |path: &Path, what: &str, e: std::io::Error| RunError::Output {
        path: path.display().to_string(),
        message: format!("{what}: {e}"),
    };
    std::fs::create_dir_all(out).map_err(|e| err(out, "cannot create the output folder", e))?;
    let probe = out.join(".write_test.tmp");
    let written = std::fs::File::create(&probe).and_then(|mut f| {
        use std::io::Write;
        f.write_all(&[0u8; 4096])?;
        f.sync_all()
    });
    let _ = std::fs::remove_file(&probe);
    written.map_err(|e| err(out, "the output folder is not writable", e))
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

fn lcm(a: u64, b: u64) -> u64 {
    (a / gcd(a, b)).saturating_mul(b)
}

/// Writes a checkpoint of the state between two steps.
fn checkpoint(
    sim: &Sim,
    pipeline: &mut [PipelineEntry],
    summary: &Summary,
    ghost_sum: f64,
    fingerprint: u64,
    opts: &RunOptions,
) -> Result<(), StepError> {
    let c = &sim.clock;
    let mut e = crate::checkpoint::begin(c.step, c.time, fingerprint, &opts.origin);
    e.f64(c.time);
    e.f64(c.dt);
    e.u64(c.step);
    e.f64(ghost_sum);
    e.u64(sim.diagnostics.len() as u64);
    for (k, v) in &sim.diagnostics {
        e.str(k);
        e.f64(*v);
    }
    crate::checkpoint::put_particles(&mut e, &sim.world);
    e.u64(pipeline.len() as u64);
    for (entry, time) in pipeline.iter_mut().zip(&summary.stages) {
        e.str(&entry.name);
        e.u64(time.calls);
        e.f64(time.seconds);
        e.bytes(&entry.stage.save_state(sim)?);
    }
    let bytes = crate::checkpoint::seal(e);
    crate::checkpoint::write(&opts.out_dir, &bytes).map_err(|message| StepError::Output {
        path: "checkpoint".into(),
        message,
    })
}

/// Puts the state of checkpoint `c` into a freshly set-up run.
fn restore(
    c: &Checkpoint,
    sim: &mut Sim,
    pipeline: &mut [PipelineEntry],
    summary: &mut Summary,
    ghost_sum: &mut f64,
) -> Result<(), String> {
    let mut d = Dec::new(&c.payload);
    sim.clock.time = d.f64()?;
    sim.clock.dt = d.f64()?;
    sim.clock.step = d.u64()?;
    // The scene follows the clock: walls and pistons where they were at that time.
    crate::kinematics::place(&sim.world, sim.clock.time);
    *ghost_sum = d.f64()?;
    let n = d.len(16)?;
    sim.diagnostics.clear();
    for _ in 0..n {
        let k = d.str()?;
        sim.diagnostics.insert(k, d.f64()?);
    }
    crate::checkpoint::get_particles(&mut d, &mut sim.world)?;
    let n = d.len(8)?;
    if n != pipeline.len() {
        return Err(format!(
            "the checkpoint has {n} stages, the scenario's pipeline {}",
            pipeline.len()
        ));
    }
    for (entry, time) in pipeline.iter_mut().zip(summary.stages.iter_mut()) {
        let name = d.str()?;
        if name != entry.name {
            return Err(format!(
                "the checkpoint has stage `{name}` where the pipeline has `{}`",
                entry.name
            ));
        }
        time.calls = d.u64()?;
        time.seconds = d.f64()?;
        let state = d.bytes()?;
        entry
            .stage
            .load_state(sim, state)
            .map_err(|e| format!("stage `{name}`: {e}"))?;
    }
    d.end()
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

/// `particle_steps`: particle-steps done by this session (not before a resume).
fn update_progress(bar: &ProgressBar, sim: &Sim, particle_steps: usize, elapsed: Duration) {
    bar.set_position((sim.clock.time * 1e4) as u64);
    let rate = particle_steps as f64 / elapsed.as_secs_f64().max(1e-9);
    bar.set_message(format!(
        "{:.3} / {:.3} s, step {}, dt {:.2e} s, {:.2e} particle-steps/s",
        sim.clock.time, sim.clock.end_time, sim.clock.step, sim.clock.dt, rate
    ));
}
