//! The runner: sets the stages up, steps the pipeline to the end time inside `tracing`
//! spans, shows progress, and writes `summary.json` and the resolved scenario — also
//! when the run stops early. A profiled run times the spans with
//! [`crate::profile::ProfileLayer`]; a traced one writes them with `tracing-chrome`.

use crate::profile::{Profile, ProfileLayer, SpanTime};
use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use serde::Serialize;
use sph_core::checkpoint::{Checkpoint, Dec, Origin, Resuming, StateError};
use sph_core::components::{Fluid, Ghost};
use sph_core::sim::Sim;
use sph_core::stage::{SetupError, StepError};
use sph_core::world::count;
use sph_output::frame::write_fluid_frame;
use sph_scenario::scenario::PipelineEntry;
use sph_scenario::scenario::Scenario;
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
    /// Show progress on stderr: a bar on a terminal, else a line every few seconds
    /// ([`PROGRESS_SECONDS_VAR`]).
    pub progress: bool,
    /// Time the spans: `summary.json`'s `stages` and [`Summary::profile_table`]. Off,
    /// no subscriber is installed and the spans cost next to nothing.
    pub profile: bool,
    /// Write a Chrome/Perfetto trace of the spans here.
    pub trace: Option<PathBuf>,
    /// Write a checkpoint about every this many seconds of simulated time.
    pub checkpoint_every: Option<f64>,
    /// Stop once the simulated time reaches this [s], writing a checkpoint.
    pub stop_at: Option<f64>,
    /// Stop after this many steps (from the start or the resume), with no checkpoint:
    /// a short look at a scenario (the fuzzer's runs). The status says so.
    pub max_steps: Option<u64>,
    /// Continue from this checkpoint ([`sph_core::checkpoint::read_latest`]); the scenario
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

/// Time spent in one stage (the busy time of its spans), with the spans it opened.
#[derive(Clone, Debug, Default, Serialize)]
pub struct StageTime {
    pub stage: String,
    pub calls: u64,
    pub seconds: f64,
    /// The stage's inner spans (grid build, scan, file writes, ...), each with its own.
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub inner: Vec<SpanTime>,
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
    /// Per pipeline entry, when the run was profiled ([`RunOptions::profile`]); else
    /// empty.
    pub stages: Vec<StageTime>,
    /// The steps `stages` covers: this session's (a resumed run profiles its own).
    pub profiled_steps: u64,
    /// Named counters from the stages, e.g. `wall_reflections`.
    pub diagnostics: std::collections::BTreeMap<String, f64>,
    /// `completed`, or why the run stopped.
    pub status: String,
}

impl Summary {
    /// The per-stage time table printed by `--profile`: a row per stage, its inner
    /// spans indented under it (their time is part of the stage's), and the total of
    /// the stages.
    pub fn profile_table(&self) -> String {
        let total: f64 = self.stages.iter().map(|s| s.seconds).sum();
        let particle_steps = (self.fluid_particles as f64 * self.profiled_steps as f64).max(1.0);
        let row = |label: &str, calls: u64, seconds: f64| {
            format!(
                "{:<16} {:>8} {:>11.3} {:>11.4} {:>6.1}% {:>13.1}\n",
                label,
                calls,
                seconds,
                1e3 * seconds / calls.max(1) as f64,
                100.0 * seconds / total.max(1e-300),
                1e9 * seconds / particle_steps
            )
        };
        fn inner(
            out: &mut String,
            rows: &[SpanTime],
            depth: usize,
            row: &dyn Fn(&str, u64, f64) -> String,
        ) {
            for s in rows {
                *out += &row(
                    &format!("{:depth$}{}", "", s.span, depth = 2 * depth),
                    s.calls,
                    s.seconds,
                );
                inner(out, &s.inner, depth + 1, row);
            }
        }
        let mut out = format!(
            "{:<16} {:>8} {:>11} {:>11} {:>7} {:>13}\n",
            "stage", "calls", "total [s]", "mean [ms]", "share", "ns/particle-step"
        );
        for s in &self.stages {
            out += &row(&s.stage, s.calls, s.seconds);
            inner(&mut out, &s.inner, 1, &row);
        }
        out += &format!(
            "{:<16} {:>8} {:>11.3} {:>11} {:>7} {:>13.1}\n",
            "total",
            self.profiled_steps,
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
    /// The checkpoint to resume from does not restore (damaged, or not this scenario's).
    #[error("output {path}: {error}")]
    Checkpoint { path: String, error: StateError },
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
    // Opened here so a FILE that cannot be created fails before the run, with its path.
    let trace_file = match &opts.trace {
        Some(path) => Some(std::fs::File::create(path).map_err(|e| RunError::Output {
            path: path.display().to_string(),
            message: e.to_string(),
        })?),
        None => None,
    };
    if trace_file.is_none() && !opts.profile {
        // No subscriber: every span is a disabled one.
        return pool.install(|| run_in_pool(scenario, opts, None));
    }
    use tracing_subscriber::prelude::*;
    keep_interest_per_thread();
    let (profile_layer, profile) = match opts.profile {
        true => {
            let (layer, profile) = ProfileLayer::new();
            (Some(layer), Some(profile))
        }
        false => (None, None),
    };
    let (chrome_layer, _flush) = match trace_file {
        Some(file) => {
            let (layer, guard) = tracing_chrome::ChromeLayerBuilder::new()
                .writer(std::io::BufWriter::new(file))
                .include_args(true)
                .build();
            (Some(layer), Some(guard))
        }
        None => (None, None),
    };
    let subscriber = tracing_subscriber::registry()
        .with(profile_layer)
        .with(chrome_layer);
    // Installed on the pool's thread that drives the run (only there: spans opened in
    // other workers' tasks are not recorded, so stages open theirs on this thread).
    pool.install(|| {
        tracing::subscriber::with_default(subscriber, || {
            run_in_pool(scenario, opts, profile.as_ref())
        })
    })
}

/// While exactly one dispatcher is registered, tracing-core caches a callsite's
/// interest as seen from the thread that reaches it first (tokio-rs/tracing#3611): a
/// run without a subscriber on another thread (a sweep's case, a test) would switch a
/// span off for this run's subscriber too. With a second, inert dispatcher registered
/// for the life of the process, the interest is taken from every registered one.
fn keep_interest_per_thread() {
    static INERT: std::sync::OnceLock<tracing::Dispatch> = std::sync::OnceLock::new();
    INERT.get_or_init(|| tracing::Dispatch::new(tracing::subscriber::NoSubscriber::default()));
}

fn run_in_pool(
    mut scenario: Scenario,
    opts: &RunOptions,
    profile: Option<&Profile>,
) -> Result<(Summary, Sim), RunError> {
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
    let fingerprint = sph_core::checkpoint::fingerprint(&resolved);
    if let Some(c) = &opts.resume {
        if c.fingerprint != fingerprint {
            return Err(RunError::Checkpoint {
                path: c.file.display().to_string(),
                error: StateError::Mismatch("the checkpoint was written for another scenario (the scenario file, its overrides or the engine's defaults changed since); rerun from the start".into()),
            });
        }
    }
    sph_core::atomic::write_atomic(&out.join("scenario.resolved.ron"), resolved.as_bytes())
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
        status: "running".into(),
        ..Summary::default()
    };
    let labels = span_labels(&pipeline);
    let mut ghost_sum = 0.0;
    if let Some(c) = &opts.resume {
        restore(c, &mut sim, &mut pipeline, &mut ghost_sum).map_err(|error| {
            RunError::Checkpoint {
                path: c.file.display().to_string(),
                error,
            }
        })?;
    }
    let start_step = sim.clock.step;
    // Checkpoints fall on steps where every stage runs next, so the stages' outputs
    // (neighbour lists, ...) are all rebuilt on the first step after a resume; a stage
    // that leaves nothing outside the checkpoint (an in-place filter, even one run
    // every 10^9 steps to switch it off) does not hold them back.
    let period = pipeline
        .iter()
        .filter(|e| !e.stage.resumes_between_runs())
        .fold(1u64, |l, e| lcm(l, e.every.max(1) as u64));
    let mut next_checkpoint = opts
        .checkpoint_every
        .map(|every| every * ((sim.clock.time / every).floor() + 1.0));
    let mut progress = Progress::new(opts.progress, &sim);
    let start = Instant::now();
    let mut failure = None;
    let mut paused = None;
    let mut limited = false;
    'steps: while sim.clock.time < sim.clock.end_time * (1.0 - 1e-12) {
        let step = sim.clock.step;
        // The step span holds the stage spans only (the profile's stage rows).
        let step_span = tracing::info_span!("step", step).entered();
        for (entry, label) in pipeline.iter_mut().zip(&labels) {
            if !step.is_multiple_of(entry.every as u64) {
                continue;
            }
            let clock = clock_bits(&sim);
            let result = {
                let _span = tracing::info_span!("stage", name = label.as_str()).entered();
                entry.stage.run(&mut sim)
            };
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
        drop(step_span);
        if sim.clock.step == step {
            failure = Some(("runner".into(), step, StepError::ClockStalled));
            break;
        }
        ghost_sum += count::<Ghost>(&sim.world) as f64;
        if step.is_multiple_of(20) {
            let steps = sim.clock.step - start_step;
            progress.update(
                &sim,
                summary.fluid_particles * steps as usize,
                start.elapsed(),
            );
        }
        let done = sim.clock.time >= sim.clock.end_time * (1.0 - 1e-12);
        if !done
            && opts
                .max_steps
                .is_some_and(|n| sim.clock.step - start_step >= n)
        {
            limited = true;
            break;
        }
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
        let written = {
            let _span = tracing::info_span!("checkpoint").entered();
            checkpoint(&sim, &mut pipeline, ghost_sum, fingerprint, opts)
        };
        if let Err(error) = written {
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
    progress.finish();
    summary.diagnostics = sim.diagnostics.clone();

    if let Some((_, step, error)) = &failure {
        summary.status = format!(
            "stopped at step {step}, t = {:.6} s: {error}",
            sim.clock.time
        );
        // Keep the offending state for inspection; a failure here must not hide the first.
        let _ = write_fluid_frame(&sim, &out.join("unstable.vtp"));
    } else if limited {
        summary.status = format!(
            "stopped after {} steps (max_steps), t = {:.6} s",
            sim.clock.step - start_step,
            sim.clock.time
        );
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
        let _span = tracing::info_span!("finish", stage = entry.name.as_str()).entered();
        if let Err(e) = entry.stage.finish(&mut sim) {
            finish_error.get_or_insert((entry.name.clone(), e));
        }
    }
    if let Some(profile) = profile {
        (summary.stages, summary.profiled_steps) =
            stage_times(&profile.report(), &pipeline, &labels);
    }
    let json = serde_json::to_string_pretty(&summary).unwrap_or_default();
    sph_core::atomic::write_atomic(&out.join("summary.json"), json.as_bytes()).map_err(io_err)?;
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

/// The label of each pipeline entry's `stage` span: its name, numbered (`density#2`)
/// when the pipeline has the stage more than once, so each entry gets its own row.
fn span_labels(pipeline: &[PipelineEntry]) -> Vec<String> {
    pipeline
        .iter()
        .enumerate()
        .map(|(i, e)| {
            let same = |o: &PipelineEntry| o.name == e.name;
            if pipeline.iter().filter(|o| same(o)).count() == 1 {
                return e.name.clone();
            }
            let k = pipeline[..i].iter().filter(|o| same(o)).count() + 1;
            format!("{}#{k}", e.name)
        })
        .collect()
}

/// Each pipeline entry's row under the `step` spans (a stage never called has zero
/// calls), and the number of steps.
fn stage_times(
    report: &[SpanTime],
    pipeline: &[PipelineEntry],
    labels: &[String],
) -> (Vec<StageTime>, u64) {
    let step = report.iter().find(|s| s.span == "step");
    let stages = pipeline
        .iter()
        .zip(labels)
        .map(|(entry, label)| {
            let row = step.and_then(|s| s.child(label));
            StageTime {
                stage: entry.name.clone(),
                calls: row.map_or(0, |r| r.calls),
                seconds: row.map_or(0.0, |r| r.seconds),
                inner: row.map(|r| r.inner.clone()).unwrap_or_default(),
            }
        })
        .collect();
    (stages, step.map_or(0, |s| s.calls))
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
    ghost_sum: f64,
    fingerprint: u64,
    opts: &RunOptions,
) -> Result<(), StepError> {
    let c = &sim.clock;
    let mut e = sph_core::checkpoint::begin(c.step, c.time, fingerprint, &opts.origin);
    e.f64(c.time);
    e.f64(c.dt);
    e.u64(c.step);
    e.f64(ghost_sum);
    e.u64(sim.diagnostics.len() as u64);
    for (k, v) in &sim.diagnostics {
        e.str(k);
        e.f64(*v);
    }
    sph_core::checkpoint::put_particles(&mut e, &sim.world);
    e.u64(pipeline.len() as u64);
    for entry in pipeline.iter_mut() {
        e.str(&entry.name);
        // Were the stage's calls and seconds; the profile covers one session, so
        // these are written as zero and skipped on reading (the format is unchanged).
        e.u64(0);
        e.f64(0.0);
        e.bytes(&entry.stage.save_state(sim)?);
    }
    let bytes = sph_core::checkpoint::seal(e);
    sph_core::checkpoint::write(&opts.out_dir, &bytes).map_err(|e| StepError::Output {
        path: "checkpoint".into(),
        message: e.to_string(),
    })
}

/// Puts the state of checkpoint `c` into a freshly set-up run.
fn restore(
    c: &Checkpoint,
    sim: &mut Sim,
    pipeline: &mut [PipelineEntry],
    ghost_sum: &mut f64,
) -> Result<(), StateError> {
    let mut d = Dec::new(&c.payload);
    sim.clock.time = d.f64()?;
    sim.clock.dt = d.f64()?;
    sim.clock.step = d.u64()?;
    // The scene follows the clock: walls and pistons where they were at that time.
    sph_core::kinematics::place(&sim.world, sim.clock.time);
    *ghost_sum = d.f64()?;
    let n = d.len(16)?;
    sim.diagnostics.clear();
    for _ in 0..n {
        let k = d.str()?;
        sim.diagnostics.insert(k, d.f64()?);
    }
    sph_core::checkpoint::get_particles(&mut d, &mut sim.world)?;
    let n = d.len(8)?;
    if n != pipeline.len() {
        return Err(StateError::Mismatch(format!(
            "the checkpoint has {n} stages, the scenario's pipeline {}",
            pipeline.len()
        )));
    }
    for entry in pipeline.iter_mut() {
        let name = d.str()?;
        if name != entry.name {
            return Err(StateError::Mismatch(format!(
                "the checkpoint has stage `{name}` where the pipeline has `{}`",
                entry.name
            )));
        }
        let (_calls, _seconds) = (d.u64()?, d.f64()?);
        let state = d.bytes()?;
        entry
            .stage
            .load_state(sim, state)
            .map_err(|error| StateError::Stage {
                stage: name,
                error: Box::new(error),
            })?;
    }
    d.end()
}

/// How often a progress line is printed when stderr is not a terminal: every 5 s of
/// wall time, or every `SPH_PROGRESS_SECONDS` (a number of seconds >= 0; 0 prints one
/// at every update, every 20 steps).
pub const PROGRESS_SECONDS_VAR: &str = "SPH_PROGRESS_SECONDS";

/// The run's progress on stderr: a bar on a terminal; a plain line every few seconds
/// when stderr goes to a file or a pipe (a batch job's log), where a bar would show
/// nothing until the end; nothing when not wanted.
enum Progress {
    Hidden,
    Bar(ProgressBar),
    Lines {
        every: Duration,
        /// When the last line was printed (the run's start before the first).
        last: Instant,
        /// The simulated time this session started from (a resume's checkpoint time).
        from: f64,
    },
}

impl Progress {
    fn new(show: bool, sim: &Sim) -> Self {
        use std::io::IsTerminal;
        if !show {
            return Self::Hidden;
        }
        if !std::io::stderr().is_terminal() {
            return Self::Lines {
                every: line_interval(),
                last: Instant::now(),
                from: sim.clock.time,
            };
        }
        let bar = ProgressBar::with_draw_target(
            Some((sim.clock.end_time * 1e4).ceil() as u64),
            ProgressDrawTarget::stderr(),
        );
        if let Ok(style) = ProgressStyle::with_template("{bar:40} t = {msg} ETA {eta}") {
            bar.set_style(style);
        }
        Self::Bar(bar)
    }

    /// `particle_steps`: particle-steps done by this session (not before a resume).
    fn update(&mut self, sim: &Sim, particle_steps: usize, elapsed: Duration) {
        let c = &sim.clock;
        let rate = particle_steps as f64 / elapsed.as_secs_f64().max(1e-9);
        match self {
            Self::Hidden => {}
            Self::Bar(bar) => {
                bar.set_position((c.time * 1e4) as u64);
                bar.set_message(format!(
                    "{:.3} / {:.3} s, step {}, dt {:.2e} s, {:.2e} particle-steps/s",
                    c.time, c.end_time, c.step, c.dt, rate
                ));
            }
            Self::Lines { every, last, from } => {
                if last.elapsed() < *every {
                    return;
                }
                *last = Instant::now();
                // Simulated time advances at a roughly steady rate once the flow is
                // going: the ETA extrapolates this session's.
                let done = c.time - *from;
                let eta = match done > 0.0 {
                    true => format!(
                        "{:.0} s",
                        (c.end_time - c.time).max(0.0) * elapsed.as_secs_f64() / done
                    ),
                    false => "unknown".into(),
                };
                eprintln!(
                    "progress: t = {:.3} / {:.3} s ({:.0} %), step {}, dt {:.2e} s, {:.2e} particle-steps/s, {:.0} s elapsed, ETA {eta}",
                    c.time,
                    c.end_time,
                    100.0 * c.time / c.end_time.max(1e-300),
                    c.step,
                    c.dt,
                    rate,
                    elapsed.as_secs_f64()
                );
            }
        }
    }

    fn finish(&self) {
        if let Self::Bar(bar) = self {
            bar.finish_and_clear();
        }
    }
}

/// The interval between progress lines: [`PROGRESS_SECONDS_VAR`] or 5 s.
fn line_interval() -> Duration {
    let default = Duration::from_secs(5);
    let Ok(text) = std::env::var(PROGRESS_SECONDS_VAR) else {
        return default;
    };
    match text.trim().parse::<f64>() {
        Ok(s) if s >= 0.0 && s.is_finite() => Duration::from_secs_f64(s.min(1e9)),
        _ => {
            eprintln!(
                "warning: {PROGRESS_SECONDS_VAR}={text:?} is not a number of seconds >= 0; printing progress every 5 s"
            );
            default
        }
    }
}
