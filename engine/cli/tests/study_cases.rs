//! `engine study FILE --case K`, `--status` and `--submit slurm --dry-run` (issue 17),
//! on the three-case study tests/scenarios/study_three.ron; none needs Slurm.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const ENGINE: &str = env!("CARGO_BIN_EXE_engine");

fn study_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/scenarios/study_three.ron")
}

fn temp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("engine-study-cases-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Removes a test's folders when it passes (kept to look at when it fails).
struct Cleanup(Vec<PathBuf>);

impl Drop for Cleanup {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            for dir in &self.0 {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
    }
}

fn engine(args: &[&str]) -> Output {
    Command::new(ENGINE).args(args).output().unwrap()
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

/// `engine study FILE --out OUT ARGS`, which must succeed; its stdout and stderr.
fn study_ok(out: &Path, args: &[&str]) -> String {
    let file = study_file();
    let mut all = vec![
        "study",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    all.extend(args);
    let o = engine(&all);
    assert!(o.status.success(), "engine {all:?}: {}", text(&o));
    text(&o)
}

fn study_err(out: &Path, args: &[&str]) -> String {
    let file = study_file();
    let mut all = vec![
        "study",
        file.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
    ];
    all.extend(args);
    let o = engine(&all);
    assert!(
        !o.status.success(),
        "engine {all:?} should fail: {}",
        text(&o)
    );
    text(&o)
}

/// The state column of case `name` in a `--status` table.
fn state_of(table: &str, name: &str) -> String {
    let line = table
        .lines()
        .find(|l| l.split_whitespace().nth(1) == Some(name))
        .unwrap_or_else(|| panic!("no row {name} in\n{table}"));
    let rest = line.split_once(name).unwrap().1.trim_start();
    [
        "stopped early",
        "not started",
        "finished",
        "running",
        "interrupted",
    ]
    .into_iter()
    .find(|s| rest.starts_with(s))
    .unwrap_or_else(|| panic!("no state in {line}"))
    .to_string()
}

#[test]
fn one_case_runs_as_the_study_runs_it_and_status_reads_the_folders() {
    let out = temp("case");
    let local = temp("case-local");
    let _cleanup = Cleanup(vec![out.clone(), local.clone()]);
    let (c1, c2, c3) = ("c0_20.0", "c0_30.0", "c0_40.0");

    let status = study_ok(&out, &["--status"]);
    for c in [c1, c2, c3] {
        assert_eq!(state_of(&status, c), "not started", "{status}");
    }
    assert!(status.contains("3 cases: 0 finished"), "{status}");

    // Case 2 by number: the folder, case.txt and summary of the study runner's.
    let said = study_ok(&out, &["--case", "2", "--threads", "1"]);
    assert!(said.contains("case 2/3 c0_30.0: completed"), "{said}");
    let dir = out.join(c2);
    for f in [
        "case.txt",
        "summary.json",
        "probes.csv",
        "final_particles.csv",
    ] {
        assert!(dir.join(f).is_file(), "{f} missing in {}", dir.display());
    }
    assert!(
        !dir.join("running.txt").exists(),
        "the marker outlives the run"
    );
    assert!(
        !out.join("study.csv").exists(),
        "--case writes no study.csv"
    );
    // The study run here gives the same probes.csv (runs are deterministic), and a
    // study over the folder skips case 2.
    study_ok(&local, &["--workers", "1", "--threads", "1"]);
    assert_eq!(
        std::fs::read(dir.join("probes.csv")).unwrap(),
        std::fs::read(local.join(c2).join("probes.csv")).unwrap()
    );
    assert_eq!(
        std::fs::read_to_string(dir.join("case.txt")).unwrap(),
        std::fs::read_to_string(local.join(c2).join("case.txt")).unwrap()
    );
    // Again, by name: skipped as finished.
    let said = study_ok(&out, &["--case", c2]);
    assert!(
        said.contains("finished earlier (completed), skipped"),
        "{said}"
    );

    // Case 1 "running" (this test's own process), case 3 killed (a pid that is gone).
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    let host = host.trim();
    for (c, pid) in [(c1, std::process::id()), (c3, dead_pid())] {
        let d = out.join(c);
        std::fs::create_dir_all(&d).unwrap();
        std::fs::copy(local.join(c).join("case.txt"), d.join("case.txt")).unwrap();
        std::fs::write(d.join("running.txt"), format!("{host} {pid} 41_{pid}\n")).unwrap();
    }
    std::fs::write(out.join(c1).join("probes.csv"), "time,P1\n0.125,3\n0.13,").unwrap();
    let status = study_ok(&out, &["--status"]);
    assert_eq!(state_of(&status, c1), "running", "{status}");
    assert!(status.contains("probes.csv at t = 0.125 s"), "{status}");
    assert_eq!(state_of(&status, c2), "finished", "{status}");
    assert_eq!(state_of(&status, c3), "interrupted", "{status}");
    // Another host's marker cannot be checked: shown as running there.
    std::fs::write(out.join(c3).join("running.txt"), "elsewhere 1 7\n").unwrap();
    let status = study_ok(&out, &["--status"]);
    assert_eq!(state_of(&status, c3), "running", "{status}");
    assert!(status.contains("another host"), "{status}");
    // A case that stopped early; a folder holding another case's run.
    std::fs::write(
        out.join(c3).join("summary.json"),
        r#"{"status": "stopped at step 9, t = 0.1 s: density guard"}"#,
    )
    .unwrap();
    std::fs::write(out.join(c1).join("case.txt"), "end_time=9\n").unwrap();
    let status = study_ok(&out, &["--status"]);
    assert_eq!(state_of(&status, c3), "stopped early", "{status}");
    assert!(status.contains("density guard"), "{status}");
    assert_eq!(state_of(&status, c1), "not started", "{status}");
    assert!(status.contains("case.txt differs"), "{status}");
    assert!(
        status.contains(
            "3 cases: 1 finished, 1 stopped early, 0 running, 0 interrupted, 1 not started"
        ),
        "{status}"
    );

    // Bad case numbers and names say which exist.
    let e = study_err(&out, &["--case", "4"]);
    assert!(
        e.contains("--case 4: study study_three has cases 1 to 3"),
        "{e}"
    );
    let e = study_err(&out, &["--case", "c0_99"]);
    assert!(e.contains("c0_20.0, c0_30.0, c0_40.0"), "{e}");
    let e = study_err(&out, &["--case", "1", "--report-only"]);
    assert!(e.contains("cannot be used with"), "{e}");
    // case.txt alone (killed before its marker was written, or by an older engine).
    std::fs::remove_file(out.join(c3).join("summary.json")).unwrap();
    std::fs::remove_file(out.join(c3).join("running.txt")).unwrap();
    let status = study_ok(&out, &["--status"]);
    assert_eq!(state_of(&status, c3), "interrupted", "{status}");
    assert!(
        status.contains("case.txt without summary.json or running.txt"),
        "{status}"
    );
}

/// The id of a process that has exited.
fn dead_pid() -> u32 {
    let mut child = Command::new("true").spawn().unwrap();
    let pid = child.id();
    child.wait().unwrap();
    pid
}

#[test]
fn submit_dry_run_writes_an_array_of_the_unfinished_cases_and_a_report_job() {
    let out = temp("dry");
    let _cleanup = Cleanup(vec![out.clone()]);
    // Case 2 finished earlier: the array holds 1 and 3 only.
    study_ok(&out, &["--case", "2", "--set", "end_time=0.2"]);
    let said = study_ok(
        &out,
        &[
            "--set",
            "end_time=0.2",
            "--threads",
            "2",
            "--submit",
            "slurm",
            "--dry-run",
            "--sbatch=--partition=long",
            "--sbatch",
            "--time=0:30:00",
        ],
    );
    assert!(said.contains("dry run: nothing submitted"), "{said}");
    assert!(
        said.contains("cases 1,3 of 3 to run (1 finished)"),
        "{said}"
    );
    let out = std::fs::canonicalize(&out).unwrap();
    let cases = std::fs::read_to_string(out.join("slurm/cases.sbatch")).unwrap();
    let report = std::fs::read_to_string(out.join("slurm/report.sbatch")).unwrap();
    let engine = std::fs::canonicalize(ENGINE).unwrap();
    let file = std::fs::canonicalize(study_file()).unwrap();
    for line in [
        "#SBATCH --array=1,3",
        "#SBATCH --cpus-per-task=2",
        "#SBATCH --partition=long",
        "#SBATCH --time=0:30:00",
        "--case \"$SLURM_ARRAY_TASK_ID\" --threads \"${SLURM_CPUS_PER_TASK:-1}\"",
        "--set end_time=0.2",
    ] {
        assert!(cases.contains(line), "{line} not in\n{cases}");
    }
    let command = format!(
        "exec {} study {} --out {}",
        engine.display(),
        file.display(),
        out.display()
    );
    assert!(cases.contains(&command), "{command} not in\n{cases}");
    assert!(report.contains(&command), "{command} not in\n{report}");
    assert!(report.contains("--report-only"), "{report}");
    assert!(!report.contains("--array"), "{report}");
    // The user's options come after ours, so that they win.
    assert!(cases.find("--partition=long") > cases.find("--cpus-per-task"));
    // Every path in the scripts is absolute.
    for script in [&cases, &report] {
        for l in script
            .lines()
            .filter(|l| l.starts_with("#SBATCH --output") || l.starts_with("#SBATCH --chdir"))
        {
            assert!(l.contains("=/"), "relative path: {l}");
        }
    }

    // Without sbatch on PATH, submitting says so.
    let empty = temp("nopath");
    let _empty = Cleanup(vec![empty.clone()]);
    std::fs::create_dir_all(&empty).unwrap();
    let o = Command::new(ENGINE)
        .args(["study", study_file().to_str().unwrap(), "--out"])
        .arg(&out)
        .args(["--set", "end_time=0.2", "--submit", "slurm"])
        .env("PATH", &empty)
        .output()
        .unwrap();
    assert!(!o.status.success());
    assert!(text(&o).contains("sbatch not found"), "{}", text(&o));
    // --sbatch needs --submit; a value that is not an option is refused.
    let e = study_err(&out, &["--sbatch=--partition=x"]);
    assert!(e.contains("--submit"), "{e}");
    let e = study_err(
        &out,
        &["--submit", "slurm", "--dry-run", "--sbatch", "partition=x"],
    );
    assert!(e.contains("starting with `-`"), "{e}");
}

#[test]
fn run_submit_dry_run_writes_a_requeueing_script() {
    let out = temp("run-dry");
    let _cleanup = Cleanup(vec![out.clone()]);
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/wave_maker.ron");
    let o = engine(&[
        scenario.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--set",
        "resolution=Spacing(0.08)",
        "--threads",
        "2",
        "--checkpoint-every",
        "0.5",
        "--submit",
        "slurm",
        "--dry-run",
        "--sbatch=--time=1:00:00",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("dry run: nothing submitted"),
        "{}",
        text(&o)
    );
    let script = std::fs::read_to_string(
        std::fs::canonicalize(&out)
            .unwrap()
            .join("slurm/run.sbatch"),
    )
    .unwrap();
    for line in [
        "#SBATCH --requeue",
        "#SBATCH --open-mode=append",
        "#SBATCH --cpus-per-task=2",
        "#SBATCH --signal=B:USR1@120",
        "#SBATCH --time=1:00:00",
        "resume \"$out\" --threads \"$threads\" --checkpoint-every 0.5 -q &",
        "--set 'resolution=Spacing(0.08)' --threads \"$threads\" --checkpoint-every 0.5 -q &",
        "scontrol requeue \"$SLURM_JOB_ID\"",
    ] {
        assert!(script.contains(line), "{line} not in\n{script}");
    }
    // A sweep does not checkpoint: refused.
    let sweep = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/anti_roll_tank.ron");
    let o = engine(&[
        sweep.to_str().unwrap(),
        "--submit",
        "slurm",
        "--dry-run",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("a sweep does not checkpoint"),
        "{}",
        text(&o)
    );
}
