//! Why a command of `engine` failed: each refusal with what it needs as data, shown as
//! the message [`crate::main_with`] prints after `error: `.

use sph_core::checkpoint::CheckpointError;
use sph_run::runner::RunError;
use sph_scenario::overrides::OverrideError;
use sph_scenario::LoadError;
use sph_study::StudyError;
use std::io;
use std::path::PathBuf;
use std::process::ExitStatus;

/// Why a run, a resume or a study of the `engine` command was refused or failed.
#[derive(Debug, thiserror::Error)]
pub enum CliError {
    /// A count option (`--threads`, `--workers`) is not a whole number >= 1.
    #[error("{option} takes a positive whole number, e.g. {option} 2")]
    NotACount { option: &'static str },
    /// A time option (`--stop-at`, `--checkpoint-every`) is not seconds > 0.
    #[error("{option} takes seconds of simulated time > 0, e.g. {option} 2.5")]
    NotSeconds { option: &'static str },
    /// A run or a resume was given `--threads 0`.
    #[error("--threads must be at least 1")]
    ZeroThreads,
    /// A study was given `--workers 0` or `--threads 0`.
    #[error("--workers and --threads must be at least 1")]
    ZeroWorkersOrThreads,
    /// `engine` was run without a scenario file or a subcommand.
    #[error("give a scenario file, e.g. `engine scenarios/dam_break.ron`")]
    NoScenario,
    /// A `--set` argument is malformed.
    #[error(transparent)]
    Override(#[from] OverrideError),
    /// The scenario or the study file is refused.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// `engine resume DIR`: `DIR` does not exist (`exists` false) or is not a folder.
    #[error(
        "{}: {} (expected a run's output folder holding checkpoint.bin, written with --checkpoint-every, --stop-at or at Ctrl-C)",
        dir.display(),
        if *exists { "not a folder" } else { "no such folder" }
    )]
    NotARunFolder { dir: PathBuf, exists: bool },
    /// `engine resume`: no usable checkpoint in the folder.
    #[error(transparent)]
    Checkpoint(#[from] CheckpointError),
    /// `engine resume`: the checkpoint does not name the scenario file it was written for.
    #[error("{}: the checkpoint does not record its scenario file (it was written by a program other than `engine`)", file.display())]
    NoScenarioRecorded { file: PathBuf },
    /// `engine resume`: the scenario the checkpoint was written for is refused now.
    #[error("{0}\n(the scenario the checkpoint was written for)")]
    ResumedScenario(#[source] LoadError),
    /// `--checkpoint-every` or `--stop-at` was given for a frequency sweep.
    #[error("--checkpoint-every and --stop-at do not apply to a sweep")]
    CheckpointsInSweep,
    /// A run could not start or write its outputs.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A run stopped at a failed step; the outputs written so far are kept in `out_dir`.
    #[error("{error}\n(outputs written so far are kept in {})", out_dir.display())]
    Stopped {
        #[source]
        error: Box<RunError>,
        out_dir: PathBuf,
    },
    /// A file (a piston flume's `waves.md`) could not be written.
    #[error("{}: {source}", path.display())]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// A study, a sweep or a wave analysis failed.
    #[error(transparent)]
    Study(#[from] StudyError),
    /// `engine study` was given `--report-only` with `--submit`.
    #[error(
        "--report-only runs nothing: drop it from --submit, whose report job writes the report"
    )]
    ReportOnlySubmit,
    /// Submitting to Slurm failed.
    #[error(transparent)]
    Slurm(#[from] SlurmError),
    /// `engine bench` failed.
    #[error(transparent)]
    Bench(#[from] BenchError),
}

/// Why `--submit slurm` could not write or submit its job scripts.
#[derive(Debug, thiserror::Error)]
pub enum SlurmError {
    /// The path of the running engine binary, which the scripts call, is unknown.
    #[error("cannot tell where this engine binary is, for the job scripts: {0}")]
    EngineExe(#[source] io::Error),
    /// An `--sbatch` value is not one option starting with `-` on one line.
    #[error("--sbatch {option:?}: give one sbatch option per --sbatch, starting with `-`, e.g. --sbatch=--partition=long")]
    BadOption { option: String },
    /// A file or folder (the scenario or study file, the output folder, a script,
    /// `jobs.txt`) could not be found, created or written.
    #[error("{}: {source}", path.display())]
    File {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// The current folder, the jobs' working folder, is unreadable.
    #[error("the current folder: {0}")]
    CurrentDir(#[source] io::Error),
    /// `sbatch` is not on `PATH`.
    #[error("sbatch not found: --submit slurm needs Slurm's commands on PATH (on a login node of the cluster); --dry-run writes the scripts without submitting")]
    SbatchNotFound(#[source] io::Error),
    /// `sbatch` could not be started; `command` is the command line as shown.
    #[error("{command}: {source}")]
    SbatchSpawn {
        command: String,
        #[source]
        source: io::Error,
    },
    /// `sbatch` refused the job.
    #[error("{command} failed ({status}): {stderr}")]
    SbatchFailed {
        command: String,
        status: ExitStatus,
        stderr: String,
    },
    /// `sbatch` succeeded but printed no job id.
    #[error("{command}: expected a job id, sbatch printed {stdout:?} {stderr:?}")]
    NoJobId {
        command: String,
        stdout: String,
        stderr: String,
    },
    /// The scenario is a frequency sweep, which does not checkpoint.
    #[error("{}: --submit slurm runs one scenario with checkpoints; a sweep does not checkpoint: run it here", path.display())]
    Sweep { path: PathBuf },
    /// `--profile` or `--trace` was given with `--submit`.
    #[error("--profile and --trace do not apply to --submit: the job runs quietly")]
    ProfileOrTrace,
    /// `--checkpoint-every` is not a positive, finite number of seconds.
    #[error("--checkpoint-every {seconds}: give a positive number of simulated seconds")]
    CheckpointEvery { seconds: f64 },
}

/// Why `engine bench` (or one of its runs) failed.
#[derive(Debug, thiserror::Error)]
pub enum BenchError {
    /// `--isa` names an instruction set this processor does not run; `available` are
    /// the SIMD sets it runs.
    #[error(
        "--isa: `{name}` is not an instruction set this processor runs; accepted: auto, {}scalar",
        available.iter().map(|a| format!("{a}, ")).collect::<String>()
    )]
    UnknownIsa {
        name: String,
        available: Vec<&'static str>,
    },
    /// `--isa` names no instruction set.
    #[error("--isa: give at least one instruction set (or auto)")]
    NoIsa,
    /// A size is not a particle count such as 5k, 20k, 1.28M or 5000.
    #[error("`{text}` is not a particle count (e.g. 5k, 20k, 1.28M)")]
    NotACount { text: String },
    /// `--threads` is empty or holds a 0.
    #[error("--threads: give counts >= 1")]
    NoThreads,
    /// The internal `--child` case is not `particles,threads,steps,end_time`.
    #[error("bad --child `{spec}`")]
    BadChild { spec: String },
    /// The scenario file could not be read.
    #[error("{}: {source}", path.display())]
    Read {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// The scenario text has no `]` before which to append the `BenchStop` stage.
    #[error("the scenario has no pipeline list to append BenchStop to")]
    NoPipeline,
    /// The `BenchStop` stage is not the last entry of the pipeline once loaded.
    #[error("BenchStop did not land at the end of the pipeline")]
    StopNotLast,
    /// A `--set` argument is malformed.
    #[error(transparent)]
    Override(#[from] OverrideError),
    /// The scenario is refused.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// A run failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The path of the running binary, which runs each case, is unknown.
    #[error(transparent)]
    CurrentExe(io::Error),
    /// A case's child process could not be started.
    #[error(transparent)]
    Spawn(io::Error),
    /// A child's measurement could not be written (child side) or read (parent side) as JSON.
    #[error(transparent)]
    Json(#[from] serde_json::Error),
    /// A case ran on another instruction set than the one asked for.
    #[error("{tag}: asked for {asked}, the run used {used}")]
    WrongIsa {
        tag: String,
        asked: String,
        used: String,
    },
    /// A case's child process failed; `stderr` is what it printed there.
    #[error("{tag}: {stderr}")]
    ChildFailed { tag: String, stderr: String },
    /// The output folder could not be created.
    #[error("{source}")]
    CreateDir {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
    /// `bench.csv` or `bench.md` could not be written.
    #[error("{source}")]
    Write {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}
