//! `--submit slurm`: a study's cases as a Slurm job array with a report job after it,
//! and a single run as a preemptible, requeueable batch job (docs/cluster.md).
//!
//! The scripts are written into the output folder (`<out>/slurm/`) with absolute paths
//! only, as the jobs run on other nodes: the output folder must be on a filesystem
//! every node sees. `--dry-run` writes them without submitting.

use crate::SlurmError;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

/// A batch system to submit to.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scheduler {
    /// Slurm (`sbatch`).
    Slurm,
}

/// Submitting to a batch system instead of running here.
#[derive(clap::Args, Debug, Clone, Default)]
pub struct SubmitArgs {
    /// Submit to a batch system instead of running here: `--submit slurm` writes the
    /// job scripts into the output folder (which every node must see) and submits them
    /// with sbatch (docs/cluster.md).
    #[arg(long, value_name = "SCHEDULER")]
    pub submit: Option<Scheduler>,
    /// An sbatch option for the submitted jobs, repeatable, e.g. --sbatch=--partition=long
    /// --sbatch=--time=2:00:00 --sbatch=--account=NAME.
    #[arg(
        long = "sbatch",
        value_name = "OPTION",
        allow_hyphen_values = true,
        requires = "submit"
    )]
    pub sbatch: Vec<String>,
    /// With --submit: write the job scripts, print the sbatch commands, submit nothing.
    #[arg(long, requires = "submit")]
    pub dry_run: bool,
}

/// Seconds before the time limit at which Slurm warns the run's job shell (USR1), which
/// passes it on to the engine as SIGTERM: time to finish a step and write a checkpoint.
/// A quarter of a shorter `--time` given with `--sbatch`.
pub const WARN_BEFORE_LIMIT: u64 = 120;

/// The time limit in seconds of a `--time`/`-t` among the sbatch options (the last one),
/// in Slurm's formats: minutes, minutes:seconds, hours:minutes:seconds, days-hours,
/// days-hours:minutes, days-hours:minutes:seconds. None if absent, unlimited or unreadable.
pub fn time_limit(options: &[String]) -> Option<u64> {
    let value = options.iter().rev().find_map(|o| {
        o.strip_prefix("--time=")
            .or_else(|| o.strip_prefix("--time "))
            .or_else(|| o.strip_prefix("-t"))
            .map(|v| v.trim_start_matches('=').trim())
    })?;
    let (days, rest) = match value.split_once('-') {
        Some((d, r)) => (Some(d.parse::<u64>().ok()?), r),
        None => (None, value),
    };
    let parts: Vec<u64> = rest
        .split(':')
        .map(|p| p.parse::<u64>().ok())
        .collect::<Option<_>>()?;
    let seconds = match (days, parts.as_slice()) {
        (None, [m]) => m * 60,
        (None, [m, s]) => m * 60 + s,
        (None, [h, m, s]) | (Some(_), [h, m, s]) => h * 3600 + m * 60 + s,
        (Some(_), [h]) => h * 3600,
        (Some(_), [h, m]) => h * 3600 + m * 60,
        _ => return None,
    };
    Some(seconds + days.unwrap_or(0) * 86_400)
}

/// Seconds before the time limit for the warning: [`WARN_BEFORE_LIMIT`], or a quarter of
/// a shorter limit given with `--sbatch=--time=...`.
fn warning(options: &[String]) -> u64 {
    time_limit(options).map_or(WARN_BEFORE_LIMIT, |t| WARN_BEFORE_LIMIT.min(t / 4).max(1))
}

/// `s` quoted for a POSIX shell.
pub fn quote(s: &str) -> String {
    if !s.is_empty()
        && s.chars()
            .all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c))
    {
        return s.to_string();
    }
    format!("'{}'", s.replace('\'', r"'\''"))
}

fn quote_path(p: &Path) -> String {
    quote(&p.display().to_string())
}

/// The engine binary, absolute, for the scripts.
fn engine_exe() -> Result<PathBuf, SlurmError> {
    std::env::current_exe()
        .and_then(std::fs::canonicalize)
        .map_err(SlurmError::EngineExe)
}

/// A [`SlurmError::File`] at `path`, for `map_err`.
fn at(path: &Path) -> impl FnOnce(std::io::Error) -> SlurmError + '_ {
    move |source| SlurmError::File {
        path: path.to_path_buf(),
        source,
    }
}

/// Checks the `--sbatch` options: each one sbatch option, on one line.
fn check_options(options: &[String]) -> Result<(), SlurmError> {
    for o in options {
        if !o.starts_with('-') || o.contains(['\n', '\r']) {
            return Err(SlurmError::BadOption { option: o.clone() });
        }
    }
    Ok(())
}

/// The `#SBATCH` lines: ours, then the user's (sbatch takes the last of a repeated option).
fn header(ours: &[String], user: &[String]) -> String {
    let mut s = String::new();
    for o in ours.iter().chain(user) {
        let _ = writeln!(s, "#SBATCH {o}");
    }
    s
}

/// Writes an executable script.
fn write_script(path: &Path, text: &str) -> Result<(), SlurmError> {
    sph_core::atomic::write_atomic(path, text.as_bytes()).map_err(at(path))?;
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).map_err(at(path))?;
    }
    Ok(())
}

/// Runs `sbatch --parsable ARGS SCRIPT` and returns the job id.
fn sbatch(args: &[String], script: &Path) -> Result<String, SlurmError> {
    let shown = format!(
        "sbatch --parsable {}{}",
        args.iter().map(|a| quote(a) + " ").collect::<String>(),
        script.display()
    );
    let out = Command::new("sbatch")
        .arg("--parsable")
        .args(args)
        .arg(script)
        .output()
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::NotFound => SlurmError::SbatchNotFound(e),
            _ => SlurmError::SbatchSpawn {
                command: shown.clone(),
                source: e,
            },
        })?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        return Err(SlurmError::SbatchFailed {
            command: shown,
            status: out.status,
            stderr: stderr.trim().to_string(),
        });
    }
    // --parsable prints `jobid` or `jobid;cluster`.
    let id = stdout.trim().split(';').next().unwrap_or("").to_string();
    if id.is_empty() || !id.chars().all(|c| c.is_ascii_digit()) {
        return Err(SlurmError::NoJobId {
            command: shown,
            stdout: stdout.trim().to_string(),
            stderr: stderr.trim().to_string(),
        });
    }
    Ok(id)
}

/// Appends a line to `<slurm_dir>/jobs.txt`, the submitted jobs `--status` reports.
fn record_job(slurm_dir: &Path, line: &str) -> Result<(), SlurmError> {
    use std::io::Write as _;
    let path = slurm_dir.join("jobs.txt");
    std::fs::OpenOptions::new()
        .create(true)
        .append(true)
        .open(&path)
        .and_then(|mut f| writeln!(f, "{line}"))
        .map_err(at(&path))
}

/// The last submission recorded in `<out>/slurm/jobs.txt`, for `--status`.
pub fn last_submission(out: &Path) -> Option<String> {
    let text = std::fs::read_to_string(out.join("slurm").join("jobs.txt")).ok()?;
    text.lines()
        .rev()
        .find(|l| !l.trim().is_empty())
        .map(str::to_string)
}

/// What a study submission needs: the study file, its command-line overrides, the
/// output folder, threads per case, the cases still to run (1-based numbers).
pub struct StudyJob<'a> {
    pub name: &'a str,
    pub study_file: &'a Path,
    pub sets: &'a [String],
    pub out: &'a Path,
    pub threads: usize,
    pub cases: usize,
    pub pending: &'a [usize],
}

/// The engine arguments common to the array and report jobs: study, --out, --set.
fn study_args(engine: &Path, job: &StudyJob, study: &Path, out: &Path) -> String {
    let mut s = format!(
        "{} study {} --out {}",
        quote_path(engine),
        quote_path(study),
        quote_path(out)
    );
    for set in job.sets {
        let _ = write!(s, " --set {}", quote(set));
    }
    s
}

/// Writes `<out>/slurm/cases.sbatch` (the job array, one task per pending case) and
/// `report.sbatch`, and submits them unless `dry_run`. Returns what to print.
pub fn submit_study(job: &StudyJob, submit: &SubmitArgs) -> Result<String, SlurmError> {
    check_options(&submit.sbatch)?;
    let engine = engine_exe()?;
    let study = std::fs::canonicalize(job.study_file).map_err(at(job.study_file))?;
    std::fs::create_dir_all(job.out).map_err(at(job.out))?;
    let out = std::fs::canonicalize(job.out).map_err(at(job.out))?;
    let cwd = std::env::current_dir().map_err(SlurmError::CurrentDir)?;
    let dir = out.join("slurm");
    std::fs::create_dir_all(&dir).map_err(at(&dir))?;
    let common = study_args(&engine, job, &study, &out);
    let threads = "\"${SLURM_CPUS_PER_TASK:-1}\"";
    let cases_script = dir.join("cases.sbatch");
    let report_script = dir.join("report.sbatch");
    let array: Vec<String> = job.pending.iter().map(usize::to_string).collect();
    let array = array.join(",");

    let ours = |name: &str, output: &str| {
        vec![
            format!("--job-name={}", quote(&format!("{name}-{}", job.name))),
            format!("--chdir={}", quote_path(&cwd)),
            format!("--output={}", quote_path(&dir.join(output))),
            "--ntasks=1".to_string(),
            format!("--cpus-per-task={}", job.threads),
        ]
    };
    if !job.pending.is_empty() {
        let mut opts = ours("study", "case-%a.%A.out");
        opts.insert(0, format!("--array={array}"));
        let text = format!(
            "#!/bin/bash\n\
             # Written by `engine study --submit slurm`: one array task per case of study `{name}`\n\
             # not finished when it was submitted; task K runs case K exactly as `engine study`\n\
             # would run it here (skipped if already finished). docs/cluster.md.\n\
             {header}\
             set -eu\n\
             echo \"case $SLURM_ARRAY_TASK_ID of study {name}: job ${{SLURM_JOB_ID:-?}} on $(hostname), $(date)\"\n\
             exec {common} --case \"$SLURM_ARRAY_TASK_ID\" --threads {threads}\n",
            name = job.name,
            header = header(&opts, &submit.sbatch),
        );
        write_script(&cases_script, &text)?;
    }
    let opts = ours("report", "report.%j.out");
    let text = format!(
        "#!/bin/bash\n\
         # Written by `engine study --submit slurm`: after the case array of study `{name}` has\n\
         # ended (however its tasks ended: afterany), writes study.csv, report.md and the\n\
         # figures from the finished cases; the others are rows `not run`. docs/cluster.md.\n\
         {header}\
         set -eu\n\
         exec {common} --report-only --workers 1 --threads {threads}\n",
        name = job.name,
        header = header(&opts, &submit.sbatch),
    );
    write_script(&report_script, &text)?;

    let mut msg = String::new();
    let status = format!(
        "{} study {} --out {}{} --status",
        engine
            .file_name()
            .map_or("engine".into(), |f| f.to_string_lossy()),
        quote_path(&study),
        quote_path(&out),
        job.sets
            .iter()
            .map(|s| format!(" --set {}", quote(s)))
            .collect::<String>()
    );
    let finished = job.cases - job.pending.len();
    if submit.dry_run {
        let _ = writeln!(
            msg,
            "dry run: nothing submitted; scripts in {}",
            dir.display()
        );
        if job.pending.is_empty() {
            let _ = writeln!(
                msg,
                "every case is finished: the report job alone would run\n  sbatch {}",
                report_script.display()
            );
        } else {
            let _ = writeln!(
                msg,
                "cases {array} of {} to run ({finished} finished); submit with\n  \
                 array=$(sbatch --parsable {})\n  \
                 sbatch --dependency=afterany:$array {}",
                job.cases,
                cases_script.display(),
                report_script.display()
            );
        }
        return Ok(msg);
    }
    let mut follow = Vec::new();
    if job.pending.is_empty() {
        let _ = writeln!(
            msg,
            "every case of study {} is finished: no case to run",
            job.name
        );
    } else {
        let array_id = sbatch(&[], &cases_script)?;
        record_job(&dir, &format!("array job {array_id}: cases {array}"))?;
        let _ = writeln!(
            msg,
            "submitted array job {array_id}: cases {array} of {} ({finished} already finished), {} CPU(s) each; logs {}",
            job.cases,
            job.threads,
            dir.join(format!("case-K.{array_id}.out")).display()
        );
        follow.push(array_id);
    }
    let dependency: Vec<String> = follow
        .first()
        .map(|id| vec![format!("--dependency=afterany:{id}")])
        .unwrap_or_default();
    let report_id = sbatch(&dependency, &report_script)?;
    record_job(&dir, &format!("report job {report_id}"))?;
    let _ = writeln!(
        msg,
        "submitted report job {report_id}{}: writes study.csv, report.md and the figures into {}",
        if follow.is_empty() {
            ""
        } else {
            ", after the array ends (afterany)"
        },
        out.display()
    );
    follow.push(report_id);
    let _ = write!(
        msg,
        "follow with: squeue -j {}\n         or: {status}",
        follow.join(",")
    );
    Ok(msg)
}

/// What a run submission needs.
pub struct RunJob<'a> {
    pub name: &'a str,
    pub scenario: &'a Path,
    pub sets: &'a [String],
    pub out: &'a Path,
    pub threads: usize,
    pub checkpoint_every: f64,
    pub stop_at: Option<f64>,
}

/// Writes `<out>/slurm/run.sbatch`, a requeueable job that starts the run, or resumes it
/// from its checkpoint when requeued, and submits it unless `dry_run`.
pub fn submit_run(job: &RunJob, submit: &SubmitArgs) -> Result<String, SlurmError> {
    check_options(&submit.sbatch)?;
    let engine = quote_path(&engine_exe()?);
    let scenario = std::fs::canonicalize(job.scenario).map_err(at(job.scenario))?;
    std::fs::create_dir_all(job.out).map_err(at(job.out))?;
    let out = std::fs::canonicalize(job.out).map_err(at(job.out))?;
    let cwd = std::env::current_dir().map_err(SlurmError::CurrentDir)?;
    let dir = out.join("slurm");
    std::fs::create_dir_all(&dir).map_err(at(&dir))?;
    let script = dir.join("run.sbatch");
    let warn = warning(&submit.sbatch);
    let opts = vec![
        format!("--job-name={}", quote(job.name)),
        format!("--chdir={}", quote_path(&cwd)),
        format!("--output={}", quote_path(&dir.join("run.%j.out"))),
        "--open-mode=append".to_string(),
        "--requeue".to_string(),
        "--ntasks=1".to_string(),
        format!("--cpus-per-task={}", job.threads),
        format!("--signal=B:USR1@{warn}"),
    ];
    let mut when = format!("--checkpoint-every {}", job.checkpoint_every);
    if let Some(t) = job.stop_at {
        let _ = write!(when, " --stop-at {t}");
    }
    let sets: String = job
        .sets
        .iter()
        .map(|s| format!(" --set {}", quote(s)))
        .collect();
    let out_q = quote_path(&out);
    let text = format!(
        r#"#!/bin/bash
# Written by `engine SCENARIO --submit slurm`: runs {scenario} into {out} as a
# preemptible job (docs/cluster.md). SIGTERM (preemption, `scancel --signal=TERM --full`,
# the time limit) reaches the engine, which writes a checkpoint and exits with code 130;
# this script then requeues the job if it is still running, and the requeued job resumes
# from the checkpoint. Outputs are those of an uninterrupted run, byte for byte.
{header}set -u
out={out_q}
threads="${{SLURM_CPUS_PER_TASK:-1}}"
echo "job ${{SLURM_JOB_ID:-?}} (restart ${{SLURM_RESTART_COUNT:-0}}) on $(hostname), $(date)"
# The engine gets SIGTERM itself; the shell only waits for it to checkpoint.
trap 'echo "job shell: SIGTERM; the engine writes a checkpoint and stops"' TERM
# The warning {warn} s before the time limit comes to this shell alone: pass it on.
trap 'echo "job shell: time limit near; asking the engine to checkpoint"; kill -TERM "$pid" 2>/dev/null' USR1
if [ -e "$out/checkpoint.bin" ] || [ -e "$out/checkpoint.prev.bin" ]; then
    {engine} resume "$out" --threads "$threads" {when} -q &
else
    {engine} {scenario_q} --out "$out"{sets} --threads "$threads" {when} -q &
fi
pid=$!
code=0
wait "$pid" || code=$?
# A trap interrupts `wait`: wait again until the engine has exited.
while kill -0 "$pid" 2>/dev/null; do
    code=0
    wait "$pid" || code=$?
done
if [ "$code" -eq 130 ]; then
    # Requeue only a job still running (a signal, or the time limit's warning): not
    # one cancelled (scancel ID), preempted (Slurm requeues it itself) or timed out.
    state=$(scontrol show job "$SLURM_JOB_ID" 2>/dev/null | grep -o 'JobState=[A-Z_]*' | cut -d= -f2)
    if [ "$state" = RUNNING ]; then
        echo "engine stopped with a checkpoint: requeueing job $SLURM_JOB_ID, $(date)"
        if scontrol requeue "$SLURM_JOB_ID"; then
            exit 0
        fi
        echo "could not requeue job $SLURM_JOB_ID; continue with: sbatch {script_q}"
    else
        echo "engine stopped with a checkpoint; job $SLURM_JOB_ID is ${{state:-gone}} (cancelled, preempted or past its time limit): not requeued from here; continue with: sbatch {script_q}"
    fi
fi
echo "engine exited with code $code, $(date)"
exit "$code"
"#,
        scenario = scenario.display(),
        out = out.display(),
        header = header(&opts, &submit.sbatch),
        scenario_q = quote_path(&scenario),
        script_q = quote_path(&script),
    );
    write_script(&script, &text)?;
    let mut msg = String::new();
    if out.join("checkpoint.bin").exists() || out.join("checkpoint.prev.bin").exists() {
        let _ = writeln!(
            msg,
            "note: {} holds a checkpoint: the job continues that run (engine resume); to start over, remove it or choose another --out",
            out.display()
        );
    }
    if submit.dry_run {
        let _ = write!(
            msg,
            "dry run: nothing submitted; submit with\n  sbatch {}",
            script.display()
        );
        return Ok(msg);
    }
    let id = sbatch(&[], &script)?;
    record_job(&dir, &format!("run job {id}"))?;
    let _ = write!(
        msg,
        "submitted job {id}: {} into {}, {} CPU(s), checkpoints every {} s of simulated time, requeued after a preemption or near its time limit\n\
         follow with: squeue -j {id}   (log: {})",
        job.name,
        out.display(),
        job.threads,
        job.checkpoint_every,
        dir.join(format!("run.{id}.out")).display()
    );
    Ok(msg)
}

/// `engine SCENARIO --submit slurm`: checks what applies to a batch job and submits it.
pub fn submit_scenario(
    args: &crate::RunArgs,
    path: &Path,
    scenario: &sph_scenario::Scenario,
    out: &Path,
) -> Result<(), SlurmError> {
    if scenario.spec.sweep.is_some() {
        return Err(SlurmError::Sweep {
            path: path.to_path_buf(),
        });
    }
    if args.profile || args.trace.is_some() {
        return Err(SlurmError::ProfileOrTrace);
    }
    let end = scenario.spec.end_time.0;
    let checkpoint_every = match args.checkpoints.checkpoint_every {
        Some(s) if s > 0.0 && s.is_finite() => s,
        Some(seconds) => return Err(SlurmError::CheckpointEvery { seconds }),
        None => end / 10.0,
    };
    let job = RunJob {
        name: &scenario.spec.name,
        scenario: path,
        sets: &args.sets,
        out,
        threads: args.threads.unwrap_or(1),
        checkpoint_every,
        stop_at: args.checkpoints.stop_at,
    };
    println!("{}", submit_run(&job, &args.submit)?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quoting_survives_the_shell() {
        assert_eq!(quote("end_time=0.5"), "end_time=0.5");
        assert_eq!(quote("a b"), "'a b'");
        assert_eq!(quote("name=\"it's\""), r#"'name="it'\''s"'"#);
        assert_eq!(quote(""), "''");
        let text = "resolution=ParticlesAcross(15) 'x' \"y\" $HOME `z`";
        let out = Command::new("sh")
            .args(["-c", &format!("printf %s {}", quote(text))])
            .output()
            .unwrap();
        assert_eq!(String::from_utf8_lossy(&out.stdout), text);
    }

    #[test]
    fn time_limits_in_slurm_formats() {
        let t = |s: &str| time_limit(&[s.to_string()]);
        assert_eq!(t("--time=10"), Some(600));
        assert_eq!(t("--time=10:30"), Some(630));
        assert_eq!(t("--time=2:00:00"), Some(7200));
        assert_eq!(t("--time=1-2"), Some(93_600));
        assert_eq!(t("--time=1-0:30"), Some(88_200));
        assert_eq!(t("--time=1-0:0:5"), Some(86_405));
        assert_eq!(t("-t 5"), Some(300));
        assert_eq!(t("--time=UNLIMITED"), None);
        assert_eq!(t("--partition=x"), None);
        // The warning: 120 s, or a quarter of a shorter limit.
        assert_eq!(warning(&[]), 120);
        assert_eq!(warning(&["--time=1".into()]), 15);
        assert_eq!(warning(&["--time=1:00:00".into()]), 120);
    }

    #[test]
    fn sbatch_options_are_one_option_each() {
        assert!(check_options(&["--partition=long".into(), "-t 10".into()]).is_ok());
        let e = check_options(&["partition=long".into()])
            .unwrap_err()
            .to_string();
        assert!(e.contains("starting with `-`"), "{e}");
        assert!(check_options(&["--x\n#SBATCH --y".into()]).is_err());
    }
}
