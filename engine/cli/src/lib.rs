//! The `engine` command line. A plugin crate builds its own binary with
//! `engine::main_with(registry)` after registering its stages.

pub mod bench;
pub mod study;

use clap::{Parser, Subcommand};
use sph_core::overrides::Override;
use sph_core::runner::{run, RunError, RunOptions};
use sph_core::{Scenario, StageRegistry};
use std::path::PathBuf;
use std::process::ExitCode;

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
    #[arg(long)]
    pub threads: Option<usize>,
    /// Print the per-stage time table at the end.
    #[arg(long)]
    pub profile: bool,
    /// Write a Chrome/Perfetto trace of the stage spans to FILE.
    #[arg(long, value_name = "FILE")]
    pub trace: Option<PathBuf>,
    /// No progress bar.
    #[arg(long, short)]
    pub quiet: bool,
}

/// Parses the command line and runs; the exit code is non-zero on any error.
pub fn main_with(registry: StageRegistry) -> ExitCode {
    let cli = Cli::parse();
    match cli.command {
        Some(Command::Stages) => {
            for (name, summary) in registry.list() {
                println!("{:<16} {summary}", sph_core::registry::camel_case(name));
            }
            ExitCode::SUCCESS
        }
        Some(Command::Bench(args)) => match bench::main(&args) {
            Ok(()) => ExitCode::SUCCESS,
            Err(message) => {
                eprintln!("error: {message}");
                ExitCode::FAILURE
            }
        },
        Some(Command::Study(args)) => match study::main(&args, &registry) {
            Ok(()) => ExitCode::SUCCESS,
            Err(message) => {
                eprintln!("error: {message}");
                ExitCode::FAILURE
            }
        },
        None => match run_scenario(&cli.run, &registry) {
            Ok(()) => ExitCode::SUCCESS,
            Err(message) => {
                eprintln!("error: {message}");
                ExitCode::FAILURE
            }
        },
    }
}

/// The `--set PATH=VALUE` arguments as overrides.
pub fn parse_sets(sets: &[String]) -> Result<Vec<Override>, String> {
    sets.iter()
        .map(|s| s.parse::<Override>().map_err(|e| e.to_string()))
        .collect()
}

/// Loads and runs one scenario, printing the headline figures.
pub fn run_scenario(args: &RunArgs, registry: &StageRegistry) -> Result<(), String> {
    let path = args
        .scenario
        .as_ref()
        .ok_or("give a scenario file, e.g. `engine scenarios/dam_break.ron`")?;
    let overrides = parse_sets(&args.sets)?;
    if args.threads == Some(0) {
        return Err("--threads must be at least 1".into());
    }
    let scenario = Scenario::load(path, &overrides, registry).map_err(|e| e.to_string())?;
    let out_dir = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out").join(&scenario.spec.name));
    if scenario.spec.sweep.is_some() {
        return run_sweep(path, &overrides, registry, &out_dir, args.threads);
    }
    let opts = RunOptions {
        out_dir: out_dir.clone(),
        threads: args.threads,
        progress: !args.quiet,
        trace: args.trace.clone(),
    };
    let result = run(scenario, &opts);
    let summary = match &result {
        Ok(s) => s.clone(),
        Err(RunError::Step { summary, .. }) => (**summary).clone(),
        Err(e) => return Err(e.to_string()),
    };
    if args.profile {
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
    result.map(|_| ()).map_err(|e| {
        format!(
            "{e}\n(outputs written so far are kept in {})",
            out_dir.display()
        )
    })
}

/// Runs a scenario's frequency sweep: cases side by side, one thread each.
fn run_sweep(
    path: &std::path::Path,
    overrides: &[Override],
    registry: &StageRegistry,
    out_dir: &std::path::Path,
    threads: Option<usize>,
) -> Result<(), String> {
    let workers = threads.unwrap_or_else(|| {
        std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get)
    });
    let start = std::time::Instant::now();
    let responses =
        sph_core::sweep::run_sweep(path, overrides, registry, out_dir, workers, &|line| {
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
