//! `engine study FILE`: runs (or resumes) a sensitivity study and writes study.csv,
//! report.md and the figures (see `sph_study::study`).

use crate::CliError;
use sph_core::StageRegistry;
use sph_study::study::{find_case, run_one_case, run_study, status, Study, StudyOptions};
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
    #[arg(long, conflicts_with = "submit", allow_negative_numbers = true, value_parser = crate::count("--workers"))]
    pub workers: Option<usize>,
    /// Threads per case [default: the cores left per worker, at least 1].
    #[arg(long, allow_negative_numbers = true, value_parser = crate::count("--threads"))]
    pub threads: Option<usize>,
    /// Run nothing: write study.csv, report.md and the figures from the cases that
    /// have finished (the others are rows `not run`), e.g. while a long study runs.
    #[arg(long)]
    pub report_only: bool,
    /// Run case K alone (its number, 1 to the number of cases, or its folder name),
    /// exactly as the study runs it: into <out>/<case>/, skipped if finished there; if it
    /// stopped early and the study has a fallback, then its fallback run into
    /// <out>/<case>__<label>/ the same way. What a task of the --submit slurm job array
    /// runs. Writes no study.csv.
    #[arg(long, value_name = "K", conflicts_with_all = ["report_only", "workers", "status", "submit"])]
    pub case: Option<String>,
    /// Print a table of the cases, read from their folders: finished, stopped early,
    /// running, interrupted, not started; the fallback run of a case that stopped early
    /// under it (K+). Runs nothing.
    #[arg(long, conflicts_with_all = ["report_only", "workers", "threads", "submit"])]
    pub status: bool,
    #[command(flatten)]
    pub submit: crate::slurm::SubmitArgs,
}

/// Runs the study and prints one line per case and where the results are.
pub fn main(args: &StudyArgs, registry: &StageRegistry) -> Result<(), CliError> {
    let overrides = crate::parse_sets(&args.sets)?;
    let study = Study::load(&args.study, &overrides, registry)?;
    if args.workers == Some(0) || args.threads == Some(0) {
        return Err(CliError::ZeroWorkersOrThreads);
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
    if args.status {
        status(&study, &out);
        return Ok(());
    }
    if let Some(k) = &args.case {
        return one_case(&study, k, &out, args.threads.unwrap_or(cores), registry);
    }
    if args.submit.submit.is_some() {
        if args.report_only {
            return Err(CliError::ReportOnlySubmit);
        }
        let pending = status::pending_cases(&study, &out);
        let job = crate::slurm::StudyJob {
            name: &study.spec.name,
            study_file: &args.study,
            sets: &args.sets,
            out: &out,
            threads: args.threads.unwrap_or(1),
            cases: study.cases.len(),
            pending: &pending,
        };
        println!("{}", crate::slurm::submit_study(&job, &args.submit)?);
        return Ok(());
    }
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
    let completed = |fallback: bool| {
        let of = rows.iter().filter(|r| r.case.fallback == fallback);
        (of.clone().filter(|r| r.completed()).count(), of.count())
    };
    let (done, cases) = completed(false);
    let again = match &study.spec.fallback {
        Some(fb) => {
            let (done, runs) = completed(true);
            format!(
                " (`{}`), {runs} ran again with `{}` and {done} of those completed",
                fb.base, fb.label
            )
        }
        None => String::new(),
    };
    println!(
        "study {}: {done} of {cases} cases completed{again}, {:.1} s wall; study.csv and report.md in {}",
        study.spec.name,
        start.elapsed().as_secs_f64(),
        out.display()
    );
    Ok(())
}

/// `--case K`: runs one case as the study would, and prints its row's status.
fn one_case(
    study: &Study,
    k: &str,
    out: &std::path::Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<(), CliError> {
    let index = find_case(study, k)?;
    let n = study.cases.len();
    let name = &study.cases[index].name;
    let dir = out.join(name);
    println!(
        "study {}: case {}/{n} {name} on {threads} thread(s), into {}",
        study.spec.name,
        index + 1,
        dir.display()
    );
    let rows = run_one_case(study, index, out, threads, registry)?;
    for (ran, row) in rows {
        let name = &row.case.name;
        if ran {
            println!(
                "case {}/{n} {name}: {} ({:.1} s wall, {:.3e} particle-steps/s)",
                index + 1,
                row.status,
                row.wall_seconds,
                row.particle_steps_per_second
            );
        } else {
            println!(
                "case {}/{n} {name}: finished earlier ({}), skipped",
                index + 1,
                row.status
            );
        }
    }
    Ok(())
}

/// `--status`: the cases' table, and the last Slurm submission if there was one.
fn status(study: &Study, out: &std::path::Path) {
    let states = status::study_status(study, out);
    let fallbacks = status::fallback_status(study, out, &states);
    println!("study {} in {}:", study.spec.name, out.display());
    print!("{}", status::status_table(study, &states, &fallbacks));
    if let Some(line) = crate::slurm::last_submission(out) {
        println!(
            "last submitted to Slurm: {line} ({})",
            out.join("slurm").join("jobs.txt").display()
        );
    }
}
