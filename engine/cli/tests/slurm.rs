//! On a real Slurm (issue 17): a single-node cluster started by tests/slurm/cluster.sh
//! in a temporary folder runs (1) a three-case study submitted with `--submit slurm`,
//! whose study.csv must equal that of the same study run here (wall times excepted), and
//! (2) a run submitted with `--submit slurm`, sent SIGTERM with `scancel --signal=TERM`
//! while it runs, requeued, resumed from its checkpoint, then sent the time limit's
//! warning (USR1 to the job shell) and requeued again, whose probes.csv and energy.csv
//! must equal an uninterrupted run's byte for byte.
//!
//! Without Slurm (sbatch, slurmctld, slurmd, munged) or root the tests print a loud
//! SKIPPED line and pass; in CI (SPH_CI=1, set by .ci/run) they fail instead, and so
//! does a cluster that cannot start.

#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::Mutex;
use std::time::{Duration, Instant};

const ENGINE: &str = env!("CARGO_BIN_EXE_engine");

/// One cluster at a time: the tests take turns (a two-core machine).
static TURN: Mutex<()> = Mutex::new(());

fn repo() -> PathBuf {
    std::fs::canonicalize(Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")).unwrap()
}

fn temp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("engine-slurm-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

fn in_ci() -> bool {
    std::env::var("SPH_CI").is_ok_and(|v| v == "1")
}

/// Why Slurm cannot be tried here, if it cannot.
fn missing() -> Option<String> {
    let absent: Vec<&str> = [
        "sbatch",
        "squeue",
        "scontrol",
        "scancel",
        "sinfo",
        "slurmctld",
        "slurmd",
        "munged",
    ]
    .into_iter()
    .filter(|exe| {
        !Command::new("sh")
            .args(["-c", &format!("command -v {exe}")])
            .output()
            .is_ok_and(|o| o.status.success())
    })
    .collect();
    if !absent.is_empty() {
        return Some(format!(
            "{} not found (apt-get install slurm-wlm munge)",
            absent.join(", ")
        ));
    }
    let uid = Command::new("id").arg("-u").output().map(|o| text(&o));
    if uid.map_or(true, |u| u.trim() != "0") {
        return Some("not root (slurmd runs the jobs)".into());
    }
    None
}

/// A running single-node cluster; stopped (by the daemons' process ids) when dropped.
struct Cluster {
    dir: PathBuf,
    conf: PathBuf,
    /// The test's output folders ([`Cluster::temp`]), removed with the cluster's own
    /// when the test passes (kept to look at when it fails).
    scratch: std::cell::RefCell<Vec<PathBuf>>,
}

impl Cluster {
    /// Starts the cluster, or returns None (after a loud SKIPPED line) where Slurm is
    /// not installed outside CI.
    fn start(tag: &str) -> Option<Self> {
        if let Some(why) = missing() {
            assert!(!in_ci(), "SPH_CI=1 but Slurm cannot run here: {why}");
            // Straight to stderr, past the test harness's capture: seen in every run.
            let _ = std::io::Write::write_all(
                &mut std::io::stderr(),
                format!("\n*** SKIPPED: Slurm test `{tag}`: {why} ***\n\n").as_bytes(),
            );
            return None;
        }
        let dir = temp(&format!("cluster-{tag}"));
        let o = Command::new(repo().join("tests/slurm/cluster.sh"))
            .arg("start")
            .arg(&dir)
            .env("SPH_SLURM_PORT", free_ports().to_string())
            .output()
            .unwrap();
        let cluster = Self {
            conf: dir.join("slurm.conf"),
            dir,
            scratch: Default::default(),
        };
        assert!(
            o.status.success(),
            "the cluster did not start: {}",
            text(&o)
        );
        Some(cluster)
    }

    /// A fresh output folder for the test, removed when the cluster is.
    fn temp(&self, tag: &str) -> PathBuf {
        let dir = temp(tag);
        self.scratch.borrow_mut().push(dir.clone());
        dir
    }

    fn cmd(&self, exe: &str) -> Command {
        let mut c = Command::new(exe);
        c.env("SLURM_CONF", &self.conf);
        c
    }

    /// `scontrol show job ID`'s `Key=Value` for `key`.
    fn job_field(&self, id: &str, key: &str) -> String {
        let o = self
            .cmd("scontrol")
            .args(["show", "job", id])
            .output()
            .unwrap();
        let t = text(&o);
        t.split_whitespace()
            .find_map(|w| w.strip_prefix(&format!("{key}=")))
            .map_or_else(|| format!("(no {key}: {})", t.trim()), str::to_string)
    }

    /// Waits until job `id` is in one of `states`, at most `limit`; returns the state.
    fn wait_state(&self, id: &str, states: &[&str], limit: Duration, log: &Path) -> String {
        let start = Instant::now();
        let mut seen = Vec::<String>::new();
        loop {
            let s = self.job_field(id, "JobState");
            if seen.last() != Some(&s) {
                eprintln!("job {id}: {s} after {:.1} s", start.elapsed().as_secs_f64());
                seen.push(s.clone());
            }
            if states.contains(&s.as_str()) {
                return s;
            }
            assert!(
                start.elapsed() < limit,
                "job {id} not {states:?} after {limit:?}: states {seen:?}; {}\nlog {}:\n{}\nslurmctld log:\n{}",
                self.job_field(id, "Reason"),
                log.display(),
                std::fs::read_to_string(log).unwrap_or_default(),
                tail(&self.dir.join("log/slurmctld.log"))
            );
            std::thread::sleep(Duration::from_millis(200));
        }
    }
}

/// The first N from 16817 up (by 2) with ports N and N + 1 free on 127.0.0.1, for
/// slurmctld and slurmd.
fn free_ports() -> u16 {
    let free = |p: u16| std::net::TcpListener::bind(("127.0.0.1", p)).is_ok();
    (16817..17817)
        .step_by(2)
        .find(|&p| free(p) && free(p + 1))
        .expect("no two free ports between 16817 and 17817")
}

/// The time of the last complete row of a probes.csv (0 if none yet).
fn last_time(p: &Path) -> f64 {
    std::fs::read_to_string(p)
        .ok()
        .and_then(|t| {
            t.lines()
                .rev()
                .skip(1) // the last line may be half written
                .find_map(|l| l.split(',').next()?.parse::<f64>().ok())
        })
        .unwrap_or(0.0)
}

fn tail(p: &Path) -> String {
    let t = std::fs::read_to_string(p).unwrap_or_default();
    let lines: Vec<&str> = t.lines().collect();
    lines[lines.len().saturating_sub(30)..].join("\n")
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // Cancels what is left, then stops the daemons by their pids.
        let o = Command::new(repo().join("tests/slurm/cluster.sh"))
            .arg("stop")
            .arg(&self.dir)
            .output();
        if let Ok(o) = o {
            eprint!("{}", text(&o));
        }
        if !std::thread::panicking() {
            for dir in self.scratch.borrow().iter().chain([&self.dir]) {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
    }
}

/// The job ids `engine ... --submit slurm` printed after `prefix` (`submitted job `).
fn job_id(printed: &str, prefix: &str) -> String {
    let rest = printed
        .split_once(prefix)
        .unwrap_or_else(|| panic!("no `{prefix}` in {printed}"))
        .1;
    rest.chars().take_while(char::is_ascii_digit).collect()
}

fn read_csv(p: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let t = std::fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let mut lines = t
        .lines()
        .map(|l| l.split(',').map(String::from).collect::<Vec<_>>());
    (lines.next().unwrap(), lines.collect())
}

#[test]
fn a_study_submitted_to_slurm_reports_what_it_reports_here() {
    let _turn = TURN.lock().unwrap_or_else(|p| p.into_inner());
    let Some(cluster) = Cluster::start("study") else {
        return;
    };
    let clock = Instant::now();
    let file = repo().join("tests/scenarios/study_three.ron");
    let (here, there) = (cluster.temp("study-here"), cluster.temp("study-slurm"));
    let o = Command::new(ENGINE)
        .args([
            "study",
            file.to_str().unwrap(),
            "--out",
            here.to_str().unwrap(),
        ])
        .args(["--workers", "2", "--threads", "1"])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let local_seconds = clock.elapsed().as_secs_f64();

    let clock = Instant::now();
    let o = cluster
        .cmd(ENGINE)
        .args([
            "study",
            file.to_str().unwrap(),
            "--out",
            there.to_str().unwrap(),
        ])
        .args(["--submit", "slurm", "--sbatch=--time=10"])
        .output()
        .unwrap();
    let printed = text(&o);
    assert!(o.status.success(), "{printed}");
    eprintln!("{printed}");
    assert!(printed.contains("cases 1,2,3 of 3"), "{printed}");
    let array = job_id(&printed, "submitted array job ");
    let report = job_id(&printed, "submitted report job ");
    let report_log = there.join(format!("slurm/report.{report}.out"));
    let state = cluster.wait_state(
        &report,
        &[
            "COMPLETED",
            "FAILED",
            "CANCELLED",
            "TIMEOUT",
            "NODE_FAIL",
            "OUT_OF_MEMORY",
        ],
        Duration::from_secs(300),
        &report_log,
    );
    let slurm_seconds = clock.elapsed().as_secs_f64();
    assert_eq!(
        state,
        "COMPLETED",
        "report job: {}",
        std::fs::read_to_string(&report_log).unwrap_or_default()
    );
    for k in 1..=3 {
        let task = format!("{array}_{k}");
        assert_eq!(
            cluster.job_field(&task, "JobState"),
            "COMPLETED",
            "array task {task}"
        );
    }
    // afterany: the report started once every task had ended.
    let report_start = cluster.job_field(&report, "StartTime");
    for k in 1..=3 {
        let end = cluster.job_field(&format!("{array}_{k}"), "EndTime");
        assert!(
            end <= report_start,
            "task {k} ended {end}, report started {report_start}"
        );
    }

    // Every metric equal; wall times and speeds are the machine's.
    let (h1, rows1) = read_csv(&here.join("study.csv"));
    let (h2, rows2) = read_csv(&there.join("study.csv"));
    assert_eq!(h1, h2);
    assert_eq!(rows1.len(), 3);
    assert_eq!(rows2.len(), 3);
    let mut compared = 0;
    for (r1, r2) in rows1.iter().zip(&rows2) {
        for ((name, a), b) in h1.iter().zip(r1).zip(r2) {
            if name != "wall_seconds" && name != "particle_steps_per_second" {
                assert_eq!(a, b, "column {name}, case {}", r1[0]);
                compared += 1;
            }
        }
        assert_eq!(
            r2[h1.iter().position(|h| h == "status").unwrap()],
            "completed"
        );
    }
    for f in ["report.md", "overlay1_kinetic_potential.png"] {
        assert!(there.join(f).is_file(), "{f} missing");
    }
    eprintln!(
        "study.csv: {compared} values equal over 3 cases ({} columns); local study {local_seconds:.1} s, \
         through Slurm {slurm_seconds:.1} s (array {array}, report {report})",
        h1.len()
    );
    // --status agrees.
    let o = Command::new(ENGINE)
        .args([
            "study",
            file.to_str().unwrap(),
            "--out",
            there.to_str().unwrap(),
            "--status",
        ])
        .output()
        .unwrap();
    let status = text(&o);
    assert!(status.contains("3 cases: 3 finished"), "{status}");
    // A case killed on another node leaves running.txt with its Slurm job: squeue tells
    // that the job has ended, so the case reads interrupted, not running.
    let case = there.join("c0_20.0");
    std::fs::remove_file(case.join("summary.json")).unwrap();
    std::fs::write(
        case.join("running.txt"),
        format!("node99 12345 {array}_1\n"),
    )
    .unwrap();
    let o = cluster
        .cmd(ENGINE)
        .args([
            "study",
            file.to_str().unwrap(),
            "--out",
            there.to_str().unwrap(),
            "--status",
        ])
        .output()
        .unwrap();
    let status = text(&o);
    assert!(
        status.contains(&format!(
            "c0_20.0  interrupted    pid 12345 (Slurm job {array}_1)"
        )),
        "{status}"
    );
    assert!(status.contains(&format!("report job {report}")), "{status}");
}

/// A coarse wave flume (630 particles) long enough to be signalled mid-run.
const RUN_SETS: [&str; 7] = [
    "resolution=Spacing(0.08)",
    "end_time=24.0",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
    "pipeline.vtk_frames.interval=1.0",
    "pipeline.neighbour_grid.sort_every=7",
    "piston.ramp=0.0",
];

#[test]
fn a_run_preempted_by_sigterm_is_requeued_and_ends_as_an_uninterrupted_run() {
    let _turn = TURN.lock().unwrap_or_else(|p| p.into_inner());
    let Some(cluster) = Cluster::start("run") else {
        return;
    };
    let scenario = repo().join("scenarios/wave_maker.ron");
    let (reference, out) = (cluster.temp("run-reference"), cluster.temp("run-slurm"));
    let sets: Vec<String> = RUN_SETS
        .iter()
        .flat_map(|s| ["--set".to_string(), s.to_string()])
        .collect();

    let clock = Instant::now();
    let o = Command::new(ENGINE)
        .arg(&scenario)
        .args(["--out", reference.to_str().unwrap(), "-q", "--threads", "1"])
        .args(&sets)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", text(&o));
    let uninterrupted = clock.elapsed().as_secs_f64();
    eprintln!("uninterrupted run here: {uninterrupted:.1} s");

    let clock = Instant::now();
    let o = cluster
        .cmd(ENGINE)
        .arg(&scenario)
        .args(["--out", out.to_str().unwrap(), "--checkpoint-every", "1.0"])
        .args(&sets)
        .args(["--submit", "slurm"])
        .output()
        .unwrap();
    let printed = text(&o);
    assert!(o.status.success(), "{printed}");
    eprintln!("{printed}");
    let id = job_id(&printed, "submitted job ");
    let out = std::fs::canonicalize(&out).unwrap();
    let log = out.join(format!("slurm/run.{id}.out"));
    // Two interruptions: SIGTERM to every process of the job, as at a preemption or the
    // time limit; then USR1 to the job shell alone, as `--signal=B:USR1@120` sends
    // before the time limit, which the shell passes on to the engine as SIGTERM.
    let rounds = [
        (["--signal=TERM", "--full"], "job shell: SIGTERM"),
        (["--signal=USR1", "--batch"], "job shell: time limit near"),
    ];
    let probes = out.join("probes.csv");
    for (round, (signal, said)) in rounds.iter().enumerate() {
        cluster.wait_state(&id, &["RUNNING"], Duration::from_secs(60), &log);
        let start = Instant::now();
        let started = format!("(restart {round})");
        while !probes.exists() || !std::fs::read_to_string(&log).is_ok_and(|t| t.contains(&started))
        {
            assert!(
                start.elapsed() < Duration::from_secs(60),
                "the run never started: {}",
                tail(&log)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        // Well under way: a quarter (then a half) of the simulated time, read from the
        // probes rather than waited out on the clock, which on a loaded machine let the
        // job finish before the signal.
        let until = 24.0 * (round + 1) as f64 / 4.0;
        let start = Instant::now();
        while last_time(&probes) < until {
            assert!(
                start.elapsed() < Duration::from_secs(300),
                "the run never reached t = {until} s: {}",
                tail(&log)
            );
            std::thread::sleep(Duration::from_millis(50));
        }
        let o = cluster
            .cmd("scancel")
            .args(signal)
            .arg(&id)
            .output()
            .unwrap();
        assert!(o.status.success(), "scancel: {}", text(&o));
        eprintln!(
            "scancel {} {id} after {:.1} s",
            signal.join(" "),
            clock.elapsed().as_secs_f64()
        );
        // Requeued: Slurm holds a requeued job back about two minutes (its BeginTime),
        // as the node refuses the job id's credentials issued in the second it was
        // revoked ("Job credential revoked"); bring that forward to 3 s after it rather
        // than wait.
        let state = cluster.wait_state(
            &id,
            &["PENDING", "COMPLETED", "FAILED", "CANCELLED"],
            Duration::from_secs(60),
            &log,
        );
        assert_eq!(state, "PENDING", "job {id} not requeued: {}", tail(&log));
        let summary = std::fs::read_to_string(out.join("summary.json")).unwrap_or_default();
        assert!(summary.contains("interrupted at step"), "{summary}");
        let log_text = std::fs::read_to_string(&log).unwrap_or_default();
        assert!(log_text.contains(said), "{said:?} not in {log_text}");
        std::thread::sleep(Duration::from_secs(3));
        let o = cluster
            .cmd("scontrol")
            .args(["update", &format!("JobId={id}"), "StartTime=now"])
            .output()
            .unwrap();
        assert!(o.status.success(), "scontrol update: {}", text(&o));
    }
    let state = cluster.wait_state(
        &id,
        &["COMPLETED", "FAILED", "CANCELLED", "TIMEOUT", "NODE_FAIL"],
        Duration::from_secs(300),
        &log,
    );
    let log_text = std::fs::read_to_string(&log).unwrap_or_default();
    assert_eq!(state, "COMPLETED", "{log_text}");
    eprintln!(
        "through Slurm with two requeues: {:.1} s\n--- {}:\n{log_text}",
        clock.elapsed().as_secs_f64(),
        log.display()
    );
    assert_eq!(cluster.job_field(&id, "Restarts"), "2");
    assert!(log_text.contains("(restart 2)"), "{log_text}");
    assert_eq!(
        log_text
            .matches("engine stopped with a checkpoint: requeueing")
            .count(),
        2,
        "{log_text}"
    );
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("\"status\": \"completed\""), "{summary}");
    // Cancelled (plain scancel: SIGTERM, then the job ends): checkpointed, not requeued.
    let cancelled = cluster.temp("run-cancelled");
    let o = cluster
        .cmd(ENGINE)
        .arg(&scenario)
        .args(["--out", cancelled.to_str().unwrap()])
        .args(&sets)
        .args(["--submit", "slurm"])
        .output()
        .unwrap();
    let id = job_id(&text(&o), "submitted job ");
    let log = std::fs::canonicalize(&cancelled)
        .unwrap()
        .join(format!("slurm/run.{id}.out"));
    cluster.wait_state(&id, &["RUNNING"], Duration::from_secs(60), &log);
    let start = Instant::now();
    while !cancelled.join("probes.csv").exists() {
        assert!(start.elapsed() < Duration::from_secs(60), "{}", tail(&log));
        std::thread::sleep(Duration::from_millis(50));
    }
    std::thread::sleep(Duration::from_secs(1));
    assert!(cluster.cmd("scancel").arg(&id).status().unwrap().success());
    let state = cluster.wait_state(
        &id,
        &["CANCELLED", "PENDING", "COMPLETED"],
        Duration::from_secs(60),
        &log,
    );
    let log_text = std::fs::read_to_string(&log).unwrap_or_default();
    assert_eq!(state, "CANCELLED", "{log_text}");
    assert!(log_text.contains("not requeued from here"), "{log_text}");
    assert!(cancelled.join("checkpoint.bin").is_file(), "{log_text}");
    for f in ["probes.csv", "energy.csv"] {
        let (a, b) = (
            std::fs::read(reference.join(f)).unwrap(),
            std::fs::read(out.join(f)).unwrap(),
        );
        assert!(
            a == b,
            "{f}: {} bytes uninterrupted, {} through the requeues; they differ",
            a.len(),
            b.len()
        );
        eprintln!("{f}: {} bytes, identical", a.len());
    }
}
