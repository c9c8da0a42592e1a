//! Where each case of a study stands, read from its folder (`engine study FILE
//! --status`): finished, stopped early, running, interrupted or not started.
//!
//! A case being run holds `running.txt` in its folder (host, process id and, under
//! Slurm, the job id), removed when the run ends. A marker left behind by a process
//! that no longer exists on this host, or by a Slurm job that `squeue` no longer shows
//! pending or running, is a case that was killed (`interrupted`); one from another host
//! that neither can tell about is shown as running there.

use super::{case_text, Case, Study};
use std::path::Path;

/// The marker of a case being run.
pub const RUNNING: &str = "running.txt";

/// The state of one case.
#[derive(Clone, Debug, PartialEq)]
pub enum CaseState {
    /// `summary.json` says `completed`.
    Finished { steps: f64, wall_seconds: f64 },
    /// `summary.json` holds another status (the density guard, a particle leaving the
    /// domain, ...): a row of the study all the same, not run again.
    StoppedEarly { status: String },
    /// A run is under way: `running.txt` names a live process on this host, or a
    /// process on another host. `time`: the last time in `probes.csv`.
    Running {
        host: String,
        pid: u32,
        job: Option<String>,
        time: Option<f64>,
    },
    /// `running.txt` names a process of this host that no longer exists: the run was
    /// killed (a cancelled or failed job, a power cut). Run it again.
    Interrupted { pid: u32, job: Option<String> },
    /// No run of this case in its folder (`case.txt` missing, or another case's).
    NotStarted { other_case: bool },
}

impl CaseState {
    /// The state's name in the table.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Finished { .. } => "finished",
            Self::StoppedEarly { .. } => "stopped early",
            Self::Running { .. } => "running",
            Self::Interrupted { .. } => "interrupted",
            Self::NotStarted { .. } => "not started",
        }
    }

    /// Whether the study runner would skip the case (its row is final).
    pub fn is_done(&self) -> bool {
        matches!(self, Self::Finished { .. } | Self::StoppedEarly { .. })
    }

    /// One line of detail for the table.
    pub fn detail(&self) -> String {
        match self {
            Self::Finished {
                steps,
                wall_seconds,
            } => format!("{steps} steps, {wall_seconds:.1} s wall"),
            Self::StoppedEarly { status } => status.clone(),
            Self::Running {
                host,
                pid,
                job,
                time,
            } => {
                let mut s = format!("on {host}, pid {pid}");
                if let Some(j) = job {
                    s += &format!(", Slurm job {j}");
                }
                if host != &this_host() {
                    s += match job.as_deref().and_then(slurm_job_active) {
                        Some(_) => " (squeue: active)",
                        None => " (another host: not checked from here)",
                    };
                }
                match time {
                    Some(t) => s + &format!("; probes.csv at t = {t} s"),
                    None => s,
                }
            }
            Self::Interrupted { pid: 0, job: None } => {
                "case.txt without summary.json or running.txt: the run was killed; run the case again"
                    .into()
            }
            Self::Interrupted { pid, job } => {
                let job = job
                    .as_ref()
                    .map_or(String::new(), |j| format!(" (Slurm job {j})"));
                format!("pid {pid}{job} is gone without a summary.json: run the case again")
            }
            Self::NotStarted { other_case: true } => {
                "the folder holds a run with other overrides (case.txt differs)".into()
            }
            Self::NotStarted { other_case: false } => String::new(),
        }
    }
}

/// This machine's host name (`/proc/sys/kernel/hostname`, else `$HOSTNAME`).
pub fn this_host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .or_else(|| std::env::var("HOSTNAME").ok())
        .map(|h| h.trim().to_string())
        .filter(|h| !h.is_empty())
        .unwrap_or_else(|| "unknown-host".into())
}

/// The text of `running.txt` for this process: `host pid [slurm-job]`.
pub fn marker_text() -> String {
    let job = std::env::var("SLURM_ARRAY_JOB_ID")
        .ok()
        .zip(std::env::var("SLURM_ARRAY_TASK_ID").ok())
        .map(|(a, t)| format!("{a}_{t}"))
        .or_else(|| std::env::var("SLURM_JOB_ID").ok());
    let mut s = format!("{} {}", this_host(), std::process::id());
    if let Some(j) = job {
        s += &format!(" {j}");
    }
    s + "\n"
}

/// Whether process `pid` exists on this host; `None` where that cannot be told
/// (no `/proc`).
fn process_alive(pid: u32) -> Option<bool> {
    Path::new("/proc/self")
        .exists()
        .then(|| Path::new(&format!("/proc/{pid}")).exists())
}

/// Whether Slurm still has job `id` (e.g. `4711_3`) pending or running, from `squeue`;
/// `None` where that cannot be told (no squeue, no answer from the controller).
fn slurm_job_active(id: &str) -> Option<bool> {
    let out = std::process::Command::new("squeue")
        .args(["-h", "-o", "%T", "-j", id])
        .stdin(std::process::Stdio::null())
        .output()
        .ok()?;
    let stdout = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        // A job the controller has forgotten.
        return String::from_utf8_lossy(&out.stderr)
            .contains("Invalid job id")
            .then_some(false);
    }
    let active = [
        "PENDING",
        "RUNNING",
        "COMPLETING",
        "CONFIGURING",
        "SUSPENDED",
        "REQUEUED",
        "REQUEUE_HOLD",
        "REQUEUE_FED",
        "RESIZING",
        "SIGNALING",
        "STAGE_OUT",
    ];
    Some(stdout.lines().any(|l| active.contains(&l.trim())))
}

/// The last complete row's time in `probes.csv`.
fn last_time(file: &Path) -> Option<f64> {
    let text = std::fs::read_to_string(file).ok()?;
    let complete = &text[..text.rfind('\n')?];
    let line = complete.rsplit('\n').next()?;
    line.split(',').next()?.trim().parse().ok()
}

/// The state of `case` from its folder `dir`.
pub fn case_state(dir: &Path, case: &Case) -> CaseState {
    let same_case = std::fs::read_to_string(dir.join("case.txt")).map(|t| t == case_text(case));
    match same_case {
        Err(_) => return CaseState::NotStarted { other_case: false },
        Ok(false) => return CaseState::NotStarted { other_case: true },
        Ok(true) => {}
    }
    if let Ok(text) = std::fs::read_to_string(dir.join("summary.json")) {
        let summary: serde_json::Value = serde_json::from_str(&text).unwrap_or_default();
        let num = |k: &str| summary.get(k).and_then(serde_json::Value::as_f64);
        let status = summary
            .get("status")
            .and_then(|s| s.as_str())
            .unwrap_or("summary.json without a status");
        return if status == "completed" {
            CaseState::Finished {
                steps: num("steps").unwrap_or(f64::NAN),
                wall_seconds: num("wall_seconds").unwrap_or(f64::NAN),
            }
        } else {
            CaseState::StoppedEarly {
                status: status.to_string(),
            }
        };
    }
    let marker = std::fs::read_to_string(dir.join(RUNNING)).unwrap_or_default();
    let mut words = marker.split_whitespace();
    let (Some(host), Some(pid)) = (words.next(), words.next().and_then(|p| p.parse().ok())) else {
        // case.txt written, no marker: a run of an engine before markers, or one killed
        // between the two writes.
        return CaseState::Interrupted { pid: 0, job: None };
    };
    let job = words.next().map(String::from);
    let gone = if host == this_host() {
        process_alive(pid) == Some(false)
    } else {
        job.as_deref().and_then(slurm_job_active) == Some(false)
    };
    if gone {
        return CaseState::Interrupted { pid, job };
    }
    CaseState::Running {
        host: host.to_string(),
        pid,
        job,
        time: last_time(&dir.join("probes.csv")),
    }
}

/// Every case's state, in case order.
pub fn study_status(study: &Study, out_dir: &Path) -> Vec<(usize, CaseState)> {
    study
        .cases
        .iter()
        .enumerate()
        .map(|(i, c)| (i + 1, case_state(&out_dir.join(&c.name), c)))
        .collect()
}

/// The state of each fallback run that is due (its case stopped early), in case order,
/// numbered as its case. Empty for a study without a fallback.
pub fn fallback_status(
    study: &Study,
    out_dir: &Path,
    states: &[(usize, CaseState)],
) -> Vec<(usize, CaseState)> {
    states
        .iter()
        .filter(|(_, st)| matches!(st, CaseState::StoppedEarly { .. }))
        .filter_map(|(k, _)| {
            let fb = study.fallbacks.get(k - 1)?;
            Some((*k, case_state(&out_dir.join(&fb.name), fb)))
        })
        .collect()
}

/// The numbers (1-based) of the cases `engine study --case K` would still run: the
/// case is not done, or it stopped early and its fallback run is not done.
pub fn pending_cases(study: &Study, out_dir: &Path) -> Vec<usize> {
    let states = study_status(study, out_dir);
    let fallbacks = fallback_status(study, out_dir, &states);
    states
        .iter()
        .filter(|(k, st)| !st.is_done() || fallbacks.iter().any(|(j, f)| j == k && !f.is_done()))
        .map(|(k, _)| *k)
        .collect()
}

/// The status table: `#`, case, state, detail, each due fallback run under its case
/// (numbered `K+`, as `--case K` runs both); then the count per state.
pub fn status_table(
    study: &Study,
    states: &[(usize, CaseState)],
    fallbacks: &[(usize, CaseState)],
) -> String {
    let width = study
        .cases
        .iter()
        .chain(&study.fallbacks)
        .map(|c| c.name.len())
        .max()
        .unwrap_or(4)
        .max(4);
    let mut s = format!("{:>4}  {:<width$}  {:<13}  detail\n", "#", "case", "state");
    let mut line = |k: String, name: &str, st: &CaseState| {
        let line = format!("{k:>4}  {name:<width$}  {:<13}  {}", st.name(), st.detail());
        s += line.trim_end();
        s.push('\n');
    };
    for (k, st) in states {
        line(k.to_string(), &study.cases[k - 1].name, st);
        for (_, f) in fallbacks.iter().filter(|(j, _)| j == k) {
            line(format!("{k}+"), &study.fallbacks[k - 1].name, f);
        }
    }
    let counts = |states: &[(usize, CaseState)]| {
        let count = |n: &str| states.iter().filter(|(_, st)| st.name() == n).count();
        [
            "finished",
            "stopped early",
            "running",
            "interrupted",
            "not started",
        ]
        .into_iter()
        .map(|n| format!("{} {n}", count(n)))
        .collect::<Vec<String>>()
        .join(", ")
    };
    s += &format!("{} cases: {}\n", states.len(), counts(states));
    if let Some(fb) = &study.spec.fallback {
        s += &format!(
            "{} fallback run(s) with `{}` (K+: run by --case K after case K stopped early): {}\n",
            fallbacks.len(),
            fb.label,
            counts(fallbacks)
        );
    }
    s
}
