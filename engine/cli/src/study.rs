//! `engine study FILE`: runs (or resumes) a sensitivity study and writes study.csv,
//! report.md and the figures (see `sph_study::study`).

use sph_core::StageRegistry;
use sph_study::study::{run_study, Study, StudyOptions};
use std::path::PathBuf;

#[derive(clap::Args, Debug, Clone)]
pub struct StudyArgs {
    /// The study file (RON), e.g. scenarios/studies/sound_speed.ron.
    pub study: PathBuf,
    /// Output folder [default: out/studies/<study name>].
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Override a value of every case's scenario, e.g. --set end_time=0.5.
    #[arg(long = "set", value_name = "PATH=VALUE")]
    pub sets: Vec<String>,
    /// Cases run at the same time [default: one per core, at most one per case].
    #[arg(long, allow_negative_numbers = true, value_parser = crate::count("--workers"))]
    pub workers: Option<usize>,
    /// Threads per case [default: the cores left per worker, at least 1].
    #[arg(long, allow_negative_numbers = true, value_parser = crate::count("--threads"))]
    pub threads: Option<usize>,
    /// Run nothing: write study.csv, report.md and the figures from the cases that
    /// have finished (the others are rows `not run`), e.g. while a long study runs.
    #[arg(long)]
    pub report_only: bool,
}

/// Runs the study and prints one line per case and where the results are.
pub fn main(args: &StudyArgs, registry: &StageRegistry) -> Result<(), String> {
    let overrides = crate::parse_sets(&args.sets)?;
    let study = Study::load(&args.study, &overrides, registry).map_err(|e| e.to_string())?;
    if args.workers == Some(0) || args.threads == Some(0) {
        return Err("--workers and --threads must be at least 1".into());
    }
    // Cases side by side, one thread each: independent runs scale without any
    // synchronisation, a small case split over threads does not (docs/studies.md).
    let workers = args
        .workers
        .unwrap_or_else(|| sph_study::parallel::default_workers(study.cases.len()));
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZeroUsize::get);
    let threads = args.threads.unwrap_or((cores / workers).max(1));
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from("out/studies").join(&study.spec.name));
    println!(
        "study {}: {} cases, {workers} at a time on {threads} thread(s) each, into {}",
        study.spec.name,
        study.cases.len(),
        out.display()
    );
    let start = std::time::Instant::now();
    let opts = StudyOptions {
        workers,
        threads,
        report_only: args.report_only,
    };
    let rows = run_study(&study, registry, &out, opts, &|line| println!("{line}"))?;
    let completed = rows.iter().filter(|r| r.completed()).count();
    println!(
        "study {}: {completed} of {} cases completed, {:.1} s wall; study.csv and report.md in {}",
        study.spec.name,
        rows.len(),
        start.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}
