//! Running a study's cases side by side, resuming finished ones, and the fallback runs.

use super::*;

/// Whether `dir` holds the finished run of `case` (its overrides and a summary).
pub fn finished(dir: &Path, case: &Case) -> bool {
    std::fs::read_to_string(dir.join("case.txt")).is_ok_and(|t| t == case_text(case))
        && dir.join("summary.json").is_file()
}

/// Runs one case into `dir` on `threads` threads; the fluid positions at the end go to
/// `final_particles.csv` (for the spatter and lost-particle metrics). A run that stops
/// early is not an error here (its summary says why); a scenario that cannot run is.
pub(crate) fn run_case(
    study: &Study,
    case: &Case,
    dir: &Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<(), StudyError> {
    std::fs::create_dir_all(dir).map_err(|e| StudyError::file(dir, e))?;
    for stale in ["summary.json", "final_particles.csv"] {
        let _ = std::fs::remove_file(dir.join(stale));
    }
    sph_core::atomic::write_atomic(&dir.join("case.txt"), case_text(case).as_bytes())
        .map_err(|e| StudyError::file(dir, e))?;
    // Who runs the case, for `--status`; removed when the run ends however it ends.
    let marker = dir.join(status::RUNNING);
    sph_core::atomic::write_atomic(&marker, status::marker_text().as_bytes())
        .map_err(|e| StudyError::file(&marker, e))?;
    let result = run_case_marked(study, case, dir, threads, registry);
    let _ = std::fs::remove_file(&marker);
    result
}

pub(crate) fn run_case_marked(
    study: &Study,
    case: &Case,
    dir: &Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<(), StudyError> {
    let scenario = Scenario::load(&study.scenario, &case.overrides, registry)?;
    let opts = RunOptions::quiet(dir, threads);
    match run_keeping_state(scenario, &opts) {
        Ok((_, sim)) => {
            let mut csv = String::from("x,y\n");
            for (p, _) in sim
                .world
                .query::<(
                    &sph_core::components::Position,
                    &sph_core::components::Fluid,
                )>()
                .iter()
            {
                let _ = writeln!(csv, "{},{}", p.0.x, p.0.y);
            }
            let path = dir.join("final_particles.csv");
            sph_core::atomic::write_atomic(&path, csv.as_bytes())
                .map_err(|e| StudyError::file(&path, e))
        }
        Err(RunError::Step { .. }) => Ok(()),
        Err(e) => Err(e.into()),
    }
}

/// The case a `--case K` argument names: its number in the study (1 to the number
/// of cases, as `engine study` and `--status` count them) or its folder name.
pub fn find_case(study: &Study, k: &str) -> Result<usize, StudyError> {
    let n = study.cases.len();
    let refused = |names: Option<Vec<String>>| StudyError::NoCase {
        given: k.to_string(),
        study: study.spec.name.clone(),
        count: n,
        names,
    };
    if let Ok(number) = k.trim().parse::<usize>() {
        return if (1..=n).contains(&number) {
            Ok(number - 1)
        } else {
            Err(refused(None))
        };
    }
    study
        .cases
        .iter()
        .position(|c| c.name == k)
        .ok_or_else(|| refused(Some(study.cases.iter().map(|c| c.name.clone()).collect())))
}

/// Whether `dir` holds a run of `case` that stopped early (its summary's status is
/// not `completed`): the case whose fallback runs.
pub fn stopped_early(dir: &Path, case: &Case) -> bool {
    matches!(
        status::case_state(dir, case),
        status::CaseState::StoppedEarly { .. }
    )
}

/// Whether a case ran now, and why it could not run if it could not.
pub(crate) type Outcome = (bool, Result<(), StudyError>);

/// Runs `case` into `<out_dir>/<case>/` unless that folder holds its finished run
/// (or, with `report_only`, at all: then the row is `not run`).
pub(crate) fn run_or_skip(
    study: &Study,
    case: &Case,
    out_dir: &Path,
    (threads, report_only): (usize, bool),
    registry: &StageRegistry,
    report: &(dyn Fn(&str) + Sync),
) -> Outcome {
    let dir = out_dir.join(&case.name);
    if finished(&dir, case) {
        report(&format!("{}: finished earlier, skipped", case.name));
        return (false, Ok(()));
    }
    if report_only {
        return (false, Err(StudyError::NotRun));
    }
    (true, run_case(study, case, &dir, threads, registry))
}

/// Case `index` and, if it stopped early and the study has a fallback, its fallback
/// run right after it (in the same worker).
pub(crate) fn run_with_fallback(
    study: &Study,
    index: usize,
    out_dir: &Path,
    how: (usize, bool),
    registry: &StageRegistry,
    report: &(dyn Fn(&str) + Sync),
) -> (Outcome, Option<Outcome>) {
    let case = &study.cases[index];
    let first = run_or_skip(study, case, out_dir, how, registry, report);
    let fallback = study
        .fallbacks
        .get(index)
        .filter(|_| stopped_early(&out_dir.join(&case.name), case))
        .map(|fb| {
            if !finished(&out_dir.join(&fb.name), fb) && !how.1 {
                report(&format!(
                    "{}: stopped early; running it again as {}",
                    case.name, fb.name
                ));
            }
            run_or_skip(study, fb, out_dir, how, registry, report)
        });
    (first, fallback)
}

/// Runs case `index` (0-based) alone, exactly as [`run_study`] runs it: into
/// `<out_dir>/<case>/` with its `case.txt`, skipped if that folder already holds its
/// finished run; then, if it stopped early and the study has a fallback, the fallback
/// run into `<out_dir>/<case>__<label>/` the same way. Writes no study.csv (the report
/// does, e.g. `--report-only`). Returns whether each ran and its row: the case's, then
/// its fallback's if that was due.
pub fn run_one_case(
    study: &Study,
    index: usize,
    out_dir: &Path,
    threads: usize,
    registry: &StageRegistry,
) -> Result<Vec<(bool, Row)>, StudyError> {
    if index >= study.cases.len() {
        return Err(StudyError::NoCase {
            given: (index + 1).to_string(),
            study: study.spec.name.clone(),
            count: study.cases.len(),
            names: None,
        });
    }
    let (first, fallback) =
        run_with_fallback(study, index, out_dir, (threads, false), registry, &|_| ());
    let mut rows = Vec::new();
    for (case, (ran, outcome)) in std::iter::once((&study.cases[index], first))
        .chain(fallback.map(|o| (&study.fallbacks[index], o)))
    {
        outcome?;
        let row = evaluate(study, case, &out_dir.join(&case.name), ran, None, registry);
        rows.push((ran, row));
    }
    Ok(rows)
}

/// How [`run_study`] runs the cases.
#[derive(Clone, Copy, Debug)]
pub struct StudyOptions {
    /// Cases run at the same time.
    pub workers: usize,
    /// Threads per case.
    pub threads: usize,
    /// Run nothing: report the cases that have finished, the others as `not run`.
    pub report_only: bool,
}

/// Runs (or resumes) every case, `workers` at a time on `threads` threads each (a
/// case's fallback run right after it, in the same worker), then writes study.csv, the
/// figures and report.md into `out_dir`. Returns the rows: each case's, followed by
/// its fallback's if it stopped early.
pub fn run_study(
    study: &Study,
    registry: &StageRegistry,
    out_dir: &Path,
    opts: StudyOptions,
    report: &(dyn Fn(&str) + Sync),
) -> Result<Vec<Row>, StudyError> {
    let StudyOptions {
        workers,
        threads,
        report_only,
    } = opts;
    std::fs::create_dir_all(out_dir).map_err(|e| StudyError::file(out_dir, e))?;
    let n = study.cases.len();
    let outcomes = crate::parallel::run_parallel(&study.cases, workers, |i, _| {
        let numbered = |line: &str| report(&format!("case {}/{n} {line}", i + 1));
        run_with_fallback(
            study,
            i,
            out_dir,
            (threads, report_only),
            registry,
            &numbered,
        )
    });
    let mut rows = Vec::new();
    for (i, (first, fallback)) in outcomes.into_iter().enumerate() {
        for (case, (ran, outcome)) in std::iter::once((&study.cases[i], first))
            .chain(fallback.map(|o| (&study.fallbacks[i], o)))
        {
            let row = evaluate(
                study,
                case,
                &out_dir.join(&case.name),
                ran,
                outcome.err().map(|e| e.to_string()),
                registry,
            );
            if ran {
                report(&format!(
                    "case {}: {} ({:.1} s wall, {:.3e} particle-steps/s)",
                    case.name, row.status, row.wall_seconds, row.particle_steps_per_second
                ));
            }
            rows.push(row);
        }
    }
    write_csv(&out_dir.join("study.csv"), study, &rows)?;
    let figures = figures::draw(study, out_dir, &rows, registry)?;
    write_report(study, out_dir, &rows, &figures, opts)?;
    Ok(rows)
}
