//! The `engine` command line. A plugin crate builds its own binary with
//! `engine::main_with(registry)` after registering its stages.

pub mod bench;
mod error;
pub mod slurm;
pub mod study;

pub use error::{BenchError, CliError, SlurmError};

use clap::{Parser, Subcommand};
use sph_core::checkpoint::Origin;
use sph_core::StageRegistry;
use sph_run::runner::{run, RunError, RunOptions};
use sph_scenario::overrides::{Override, OverrideError};
use sph_scenario::Scenario;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, OnceLock};

#[derive(Parser, Debug)]
#[command(
    name = "engine",
    version,
    about = "Weakly-compressible SPH for violent free-surface flow"
)]
#[command(args_conflicts_with_subcommands = true)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Option<Command>,
    #[command(flatten)]
    pub run: RunArgs,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// List the registered stages.
    Stages,
    /// Benchmark the dam break over sizes and thread counts (bench.csv, bench.md).
    Bench(bench::BenchArgs),
    /// Run a sensitivity study (scenarios/studies/*.ron): study.csv, report.md, figures.
    Study(study::StudyArgs),
    /// Continue a run from the newest checkpoint in its output folder.
    Resume(ResumeArgs),
}

/// Continuing a run from its checkpoint.
#[derive(clap::Args, Debug, Clone)]
pub struct ResumeArgs {
    /// The run's output folder (holding checkpoint.bin).
    pub dir: PathBuf,
    /// Worker threads [default: one per core]; results do not depend on it.
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = count("--threads"))]
    pub threads: Option<usize>,
    #[command(flatten)]
    pub checkpoints: CheckpointArgs,
    /// Print the per-stage time table at the end.
    #[arg(long)]
    pub profile: bool,
    /// No progress (a bar on a terminal, else a line every 5 s).
    #[arg(long, short)]
    pub quiet: bool,
}

/// When to write checkpoints.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct CheckpointArgs {
    /// Write a checkpoint about every SECONDS of simulated time (checkpoint.bin in the
    /// output folder, the previous one kept as checkpoint.prev.bin).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true,
          value_parser = seconds("--checkpoint-every"))]
    pub checkpoint_every: Option<f64>,
    /// Stop once the simulated time reaches SECONDS, with a checkpoint
    /// (continue with `engine resume DIR`).
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true,
          value_parser = seconds("--stop-at"))]
    pub stop_at: Option<f64>,
}

/// Running one scenario.
#[derive(clap::Args, Debug, Clone)]
pub struct RunArgs {
    /// The scenario file (RON), e.g. scenarios/dam_break.ron.
    pub scenario: Option<PathBuf>,
    /// Output folder [default: out/<scenario name>].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Override a scenario value, e.g. --set end_time=0.5 --set pipeline.reinitialise.every=5.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub sets: Vec<String>,
    /// Worker threads [default: one per core].
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = count("--threads"))]
    pub threads: Option<usize>,
    /// Print the per-stage time table at the end (stages and their inner spans).
    #[arg(long)]
    pub profile: bool,
    /// Write a Chrome/Perfetto trace of the step, stage and inner spans to FILE.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// No progress (a bar on a terminal, else a line every 5 s).
    #[arg(long, short)]
    pub quiet: bool,
    #[command(flatten)]
    pub checkpoints: CheckpointArgs,
    #[command(flatten)]
    pub submit: slurm::SubmitArgs,
}

/// Parses the command line and runs; the exit code is non-zero on any error.
pub fn main_with(registry: StageRegistry) -> ExitCode {
    let cli = Cli::parse();
    let done = |()| ExitCode::SUCCESS;
    let result = match cli.command {
        Some(Command::Stages) => {
            for (name, summary) in registry.list() {
                println!("{:<16} {summary}", sph_core::registry::camel_case(name));
            }
            Ok(ExitCode::SUCCESS)
        }
        Some(Command::Bench(args)) => bench::main(&args).map(done).map_err(CliError::from),
        Some(Command::Resume(args)) => resume(&args, &registry),
        Some(Command::Study(args)) => study::main(&args, &registry).map(done),
        None => run_scenario(&cli.run, &registry),
    };
    result.unwrap_or_else(|message| {
        eprintln!("error: {message}");
        ExitCode::FAILURE
    })
}

/// The space dimensions a command line (the program's name first) asks for: those of
/// the scenario it runs or benches (its `dimensions` field, after `--set`), of the run
/// folder it resumes (its checkpoint's), or of a study's base scenario; 2 when it names
/// none or it cannot be read (the 2D build then reports what is wrong). The `engine`
/// binary runs the build of that dimension.
pub fn dimensions_asked<I, T>(args: I) -> u32
where
    I: IntoIterator<Item = T>,
    T: Into<std::ffi::OsString> + Clone,
{
    let Ok(cli) = Cli::try_parse_from(args) else {
        return 2;
    };
    let of_file = |path: &std::path::Path, sets: &[String]| {
        let overrides = parse_sets(sets).unwrap_or_default();
        std::fs::read_to_string(path).map_or(2, |t| sph_scenario::dimensions_of(&t, &overrides))
    };
    match &cli.command {
        None => cli
            .run
            .scenario
            .as_deref()
            .map_or(2, |p| of_file(p, &cli.run.sets)),
        Some(Command::Resume(a)) => sph_core::checkpoint::dimensions_in(&a.dir).unwrap_or(2),
        Some(Command::Bench(a)) => of_file(&a.scenario, &a.sets),
        Some(Command::Study(a)) => std::fs::read_to_string(&a.study)
            .ok()
            .and_then(|t| {
                sph_scenario::scenario::parse_ron::<sph_study::study::StudySpec>(&t, "").ok()
            })
            .map_or(2, |spec| {
                let dir = a.study.parent().unwrap_or(std::path::Path::new("."));
                let mut sets = spec.set.clone();
                sets.extend(a.sets.iter().cloned());
                of_file(&dir.join(&spec.scenario), &sets)
            }),
        Some(Command::Stages) => 2,
    }
}

/// Exit code of a run stopped by Ctrl-C (128 + SIGINT), after its checkpoint.
pub const INTERRUPTED: u8 = 130;

/// The flag a first Ctrl-C (SIGINT; also SIGTERM and SIGHUP, as a batch system or a
/// closed terminal sends) sets: the run writes a checkpoint at
/// the next step where it can and exits. A second Ctrl-C exits at once. Installed once.
fn interrupt_flag() -> Option<Arc<AtomicBool>> {
    static FLAG: OnceLock<Option<Arc<AtomicBool>>> = OnceLock::new();
    FLAG.get_or_init(|| {
        let flag = Arc::new(AtomicBool::new(false));
        let seen = flag.clone();
        let installed = ctrlc::set_handler(move || {
            if seen.swap(true, Ordering::SeqCst) {
                eprintln!("\ninterrupted again: exiting without a checkpoint");
                std::process::exit(INTERRUPTED as i32);
            }
            eprintln!("\ninterrupted: writing a checkpoint, then stopping (Ctrl-C again to exit at once)");
        });
        match installed {
            Ok(()) => Some(flag),
            Err(e) => {
                eprintln!("warning: no Ctrl-C handler ({e}); Ctrl-C will stop the run without a checkpoint");
                None
            }
        }
    })
    .clone()
}

/// The parser of a count option (`--threads`, `--workers`): a whole number >= 1, with
/// an error that names the option and what it takes. Used with
/// `allow_negative_numbers`, so that `--threads -1` reaches it instead of clap's
/// "unexpected argument '-1'".
pub fn count(
    option: &'static str,
) -> impl Fn(&str) -> Result<usize, CliError> + Clone + Send + Sync + 'static {
    move |text| match text.trim().parse::<usize>() {
        Ok(n) if n >= 1 => Ok(n),
        _ => Err(CliError::NotACount { option }),
    }
}

/// The parser of a time option (`--stop-at`, `--checkpoint-every`): seconds of
/// simulated time > 0, with an error that names the option.
pub fn seconds(
    option: &'static str,
) -> impl Fn(&str) -> Result<f64, CliError> + Clone + Send + Sync + 'static {
    move |text| match text.trim().parse::<f64>() {
        Ok(t) if t > 0.0 && t.is_finite() => Ok(t),
        _ => Err(CliError::NotSeconds { option }),
    }
}

/// The `--set PATH=VALUE` arguments as overrides.
pub fn parse_sets(sets: &[String]) -> Result<Vec<Override>, OverrideError> {
    sets.iter().map(|s| s.parse::<Override>()).collect()
}

/// Continues a run from the newest usable checkpoint in `args.dir`.
pub fn resume(args: &ResumeArgs, registry: &StageRegistry) -> Result<ExitCode, CliError> {
    if args.threads == Some(0) {
        return Err(CliError::ZeroThreads);
    }
    if !args.dir.is_dir() {
        return Err(CliError::NotARunFolder {
            dir: args.dir.clone(),
            exists: args.dir.exists(),
        });
    }
    let (checkpoint, notes) = sph_core::checkpoint::read_latest(&args.dir)?;
    for note in notes {
        eprintln!("note: {note}");
    }
    let origin = checkpoint.origin.clone();
    if origin.scenario.as_os_str().is_empty() {
        return Err(CliError::NoScenarioRecorded {
            file: checkpoint.file.clone(),
        });
    }
    let overrides = parse_sets(&origin.sets)?;
    let scenario = Scenario::load(&origin.scenario, &overrides, registry)
        .map_err(CliError::ResumedScenario)?;
    eprintln!(
        "resuming {} from t = {} s (step {}) in {}",
        origin.scenario.display(),
        checkpoint.time,
        checkpoint.step,
        args.dir.display()
    );
    let opts = RunOptions {
        out_dir: args.dir.clone(),
        threads: args.threads,
        progress: !args.quiet,
        profile: args.profile,
        checkpoint_every: args.checkpoints.checkpoint_every,
        stop_at: args.checkpoints.stop_at,
        resume: Some(checkpoint),
        interrupt: interrupt_flag(),
        origin,
        ..RunOptions::default()
    };
    execute(scenario, &opts)
}

/// Loads and runs one scenario, printing the headline figures.
pub fn run_scenario(args: &RunArgs, registry: &StageRegistry) -> Result<ExitCode, CliError> {
    let path = args.scenario.as_ref().ok_or(CliError::NoScenario)?;
    let overrides = parse_sets(&args.sets)?;
    if args.threads == Some(0) {
        return Err(CliError::ZeroThreads);
    }
    let scenario = Scenario::load(path, &overrides, registry)?;
    let out_dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&scenario.spec.name));
    if args.submit.submit.is_some() {
        slurm::submit_scenario(args, path, &scenario, &out_dir)?;
        return Ok(ExitCode::SUCCESS);
    }
    if scenario.spec.sweep.is_some() {
        if args.checkpoints.checkpoint_every.is_some() || args.checkpoints.stop_at.is_some() {
            return Err(CliError::CheckpointsInSweep);
        }
        return run_sweep(path, &overrides, registry, &out_dir, args.threads)
            .map(|()| ExitCode::SUCCESS);
    }
    let opts = RunOptions {
        out_dir,
        threads: args.threads,
        progress: !args.quiet,
        profile: args.profile,
        trace: args.trace.clone(),
        checkpoint_every: args.checkpoints.checkpoint_every,
        stop_at: args.checkpoints.stop_at,
        interrupt: interrupt_flag(),
        origin: Origin {
            scenario: std::fs::canonicalize(path).unwrap_or_else(|_| path.clone()),
            sets: args.sets.clone(),
        },
        ..RunOptions::default()
    };
    execute(scenario, &opts)
}

/// Runs a loaded scenario and prints the headline figures; the exit code is
/// [`INTERRUPTED`] after a Ctrl-C (with its checkpoint written).
fn execute(scenario: Scenario, opts: &RunOptions) -> Result<ExitCode, CliError> {
    let out_dir = &opts.out_dir;
    let waves = sph_study::waves::WaveTheory::from_scenario(&scenario);
    let reference = scenario
        .spec
        .reference
        .clone()
        .zip(scenario.reference_file());
    let units = sph_study::reference::ColumnUnits::of(&scenario);
    // A failed step still has a summary to print; any other failure has none.
    let (summary, stopped) = match run(scenario, opts) {
        Ok(summary) => (summary, None),
        Err(e) => match &e {
            RunError::Step { summary, .. } => ((**summary).clone(), Some(e)),
            _ => return Err(CliError::Run(e)),
        },
    };
    if opts.profile {
        println!("{}", summary.profile_table());
    }
    println!(
        "{}: {} fluid particles, {} steps to t = {:.4} s in {:.2} s wall, {:.3e} particle-steps/s on {} threads; outputs in {}",
        summary.scenario,
        summary.fluid_particles,
        summary.steps,
        summary.simulated_time,
        summary.wall_seconds,
        summary.particle_steps_per_second,
        summary.threads,
        out_dir.display()
    );
    if summary.status != "completed" && stopped.is_none() {
        println!("{}", summary.status);
    }
    if let (Some(waves), true) = (&waves, summary.status == "completed") {
        report_waves(waves, out_dir)?;
    }
    // Also for a run that stopped: the comparison up to where it got.
    if let Some((spec, file)) = &reference {
        let probes = out_dir.join("probes.csv");
        if probes.exists() {
            let report = sph_study::reference::compare_files(spec, file, &probes)?;
            report.write(out_dir, &units)?;
            println!("{} (reference.md)", report.summary());
        }
    }
    let interrupted = summary.status.starts_with("interrupted");
    match stopped {
        Some(error) => Err(CliError::Stopped {
            error: Box::new(error),
            out_dir: out_dir.clone(),
        }),
        None if interrupted => Ok(ExitCode::from(INTERRUPTED)),
        None => Ok(ExitCode::SUCCESS),
    }
}

/// A piston flume's gauges against Biesel and the dispersion relation: a line on the
/// terminal and `waves.md` beside `probes.csv`.
fn report_waves(
    waves: &sph_study::waves::WaveTheory,
    out_dir: &std::path::Path,
) -> Result<(), CliError> {
    let probes = out_dir.join("probes.csv");
    if !probes.exists() {
        return Ok(());
    }
    let report = waves.measure(&probes)?;
    let path = out_dir.join("waves.md");
    if let Err(source) = sph_core::atomic::write_atomic(&path, report.markdown().as_bytes()) {
        return Err(CliError::Write { path, source });
    }
    println!("{} (waves.md)", report.summary());
    Ok(())
}

/// Runs a scenario's frequency sweep: cases side by side, one thread each.
fn run_sweep(
    path: &std::path::Path,
    overrides: &[Override],
    registry: &StageRegistry,
    out_dir: &std::path::Path,
    threads: Option<usize>,
) -> Result<(), CliError> {
    let workers = threads.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let start = std::time::Instant::now();
    let responses =
        sph_study::sweep::run_sweep(path, overrides, registry, out_dir, workers, &|line| {
            println!("{line}")
        })?;
    println!(
        "sweep: {} cases in {:.1} s wall on {workers} workers; response.csv and response.png in {}",
        responses.len(),
        start.elapsed().as_secs_f64(),
        out_dir.display()
    );
    Ok(())
}
