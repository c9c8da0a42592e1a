//! The `engine` command's own errors and its progress output, run as a user runs it:
//! the binary with its stderr piped (not a terminal).

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const ENGINE: &str = env!("CARGO_BIN_EXE_engine");

fn shipped(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../scenarios")
        .join(name)
}

fn temp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("engine-cli-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn engine(args: &[&str], env: &[(&str, &str)]) -> Output {
    let mut c = Command::new(ENGINE);
    c.args(args).env_remove("SPH_PROGRESS_SECONDS");
    for (k, v) in env {
        c.env(k, v);
    }
    c.output().expect("the engine binary runs")
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The arguments of a coarse dam break (450 particles) on `threads` threads, quiet.
fn coarse_dam(threads: &str) -> [&str; 5] {
    [
        "--set",
        "resolution=ParticlesAcross(30)",
        "--threads",
        threads,
        "-q",
    ]
}

/// A coarse, short dam break that writes next to nothing.
fn short_run(out: &Path) -> Vec<String> {
    let mut args: Vec<String> = vec![
        shipped("dam_break.ron").display().to_string(),
        "--out".into(),
        out.display().to_string(),
        "--threads".into(),
        "1".into(),
    ];
    for set in [
        "resolution=ParticlesAcross(20)",
        "end_time=0.05",
        "pipeline.probe.plots=false",
        "pipeline.energy.plots=false",
        "pipeline.vtk_frames.interval=1.0",
    ] {
        args.push("--set".into());
        args.push(set.into());
    }
    args
}

#[test]
fn progress_is_printed_as_lines_when_stderr_is_not_a_terminal() {
    let out = temp("progress");
    let args = short_run(&out);
    let args: Vec<&str> = args.iter().map(String::as_str).collect();
    let run = engine(&args, &[("SPH_PROGRESS_SECONDS", "0")]);
    let err = stderr(&run);
    assert!(run.status.success(), "{err}");
    let lines: Vec<&str> = err
        .lines()
        .filter(|l| l.starts_with("progress: "))
        .collect();
    assert!(lines.len() >= 3, "expected progress lines, got:\n{err}");
    for line in &lines {
        for part in [" / 0.050 s (", "step ", "particle-steps/s", "elapsed, ETA "] {
            assert!(line.contains(part), "`{part}` missing from `{line}`");
        }
        // One line each, no terminal control characters from a bar.
        assert!(!line.contains('\r') && !line.contains('\u{1b}'), "{line:?}");
    }
    // Quiet: none.
    let quiet = engine(
        &[&args[..], &["-q"]].concat(),
        &[("SPH_PROGRESS_SECONDS", "0")],
    );
    assert!(quiet.status.success());
    assert!(!stderr(&quiet).contains("progress: "), "{}", stderr(&quiet));
    // A bad interval is reported, and the run goes on with the default.
    let bad = engine(&args, &[("SPH_PROGRESS_SECONDS", "-1")]);
    assert!(bad.status.success());
    assert!(
        stderr(&bad).contains("SPH_PROGRESS_SECONDS=\"-1\" is not a number of seconds >= 0"),
        "{}",
        stderr(&bad)
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn negative_numbers_get_a_clear_error() {
    let dam = shipped("dam_break.ron").display().to_string();
    let study = shipped("studies/kernel.ron").display().to_string();
    for (args, expect) in [
        (
            vec![dam.as_str(), "--threads", "-1"],
            "--threads takes a positive whole number",
        ),
        (
            vec![dam.as_str(), "--threads", "0"],
            "--threads takes a positive whole number",
        ),
        (
            vec![dam.as_str(), "--stop-at", "-1"],
            "--stop-at takes seconds of simulated time > 0",
        ),
        (
            vec![dam.as_str(), "--checkpoint-every", "-0.5"],
            "--checkpoint-every takes seconds of simulated time > 0",
        ),
        (
            vec!["resume", "somewhere", "--threads", "-2"],
            "--threads takes a positive whole number",
        ),
        (
            vec!["study", study.as_str(), "--workers", "-2"],
            "--workers takes a positive whole number",
        ),
        (
            vec!["bench", "--threads", "1,-1"],
            "--threads takes a positive whole number",
        ),
    ] {
        let o = engine(&args, &[]);
        let err = stderr(&o);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(
            err.contains(expect),
            "{args:?}: `{expect}` missing from:\n{err}"
        );
        assert!(!err.contains("unexpected argument"), "{args:?}: {err}");
    }
}

#[test]
fn resume_says_when_the_folder_does_not_exist() {
    let missing = temp("no-such-run");
    let o = engine(&["resume", &missing.display().to_string()], &[]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains(&format!(
            "{}: no such folder (expected a run's output folder holding checkpoint.bin",
            missing.display()
        )),
        "{err}"
    );
    let file = shipped("dam_break.ron");
    let o = engine(&["resume", &file.display().to_string()], &[]);
    assert!(
        stderr(&o).contains(": not a folder (expected"),
        "{}",
        stderr(&o)
    );
}

#[test]
fn a_missing_study_file_is_called_the_study_file() {
    let o = engine(&["study", "no_such_study.ron"], &[]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains("error: no_such_study.ron: cannot read the study file:"),
        "{err}"
    );
    assert!(!err.contains("field `study`"), "{err}");
}

#[test]
fn set_errors_name_the_set_argument() {
    let dam = shipped("dam_break.ron").display().to_string();
    let set = "pipeline.forces.terms.riemann_pressure.limitr=1.0";
    let o = engine(&[&dam, "--set", set], &[]);
    let err = stderr(&o);
    assert!(!o.status.success());
    assert!(
        err.contains(&format!("dam_break.ron: --set {set}: field `limitr`: ")),
        "{err}"
    );
    assert!(err.contains("did you mean `limiter`?"), "{err}");
    let o = engine(&[&dam, "--set", "reinitialise.every"], &[]);
    let err = stderr(&o);
    assert!(
        err.contains(
            "expected `path=value`, e.g. `end_time=0.5` or `pipeline.reinitialise.every=5`"
        ),
        "{err}"
    );
}

/// README's command list names every subcommand of `engine`.
#[test]
fn readme_lists_every_command() {
    use clap::CommandFactory;
    let readme =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../README.md"))
            .expect("README.md");
    let start = readme
        .find("## Command line")
        .expect("a Command line section");
    let block = &readme[start..];
    let block = &block[..block.find("```\n\n").expect("the command block ends")];
    for sub in engine::Cli::command().get_subcommands() {
        let line = format!("\nengine {}", sub.get_name());
        assert!(
            block.contains(&line),
            "README's command list lacks `engine {}`",
            sub.get_name()
        );
    }
}

/// An unstable run through the command line (issue 28): it exits non-zero, says where
/// and when on stderr, writes `summary.json` with the reason and `unstable.vtp` with
/// the fluid at that moment; run in a folder that already holds an earlier run's
/// checkpoints, it leaves them byte for byte as they were.
#[test]
fn an_unstable_run_stops_with_its_diagnostic_and_keeps_earlier_checkpoints() {
    let out = temp("unstable");
    let dam = shipped("dam_break.ron").display().to_string();
    let dir = out.display().to_string();
    let coarse = coarse_dam("2");
    let mut first = vec![&dam[..], "--out", &dir, "--set", "end_time=0.3"];
    first.extend(["--checkpoint-every", "0.1"]);
    first.extend(coarse);
    let o = engine(&first, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let kept: Vec<(&str, Vec<u8>)> = ["checkpoint.bin", "checkpoint.prev.bin"]
        .into_iter()
        .map(|f| {
            (
                f,
                std::fs::read(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}")),
            )
        })
        .collect();
    // A density guard of 2 %: the impact at the right wall (t = 0.6 s) trips it.
    let mut second = vec![&dam[..], "--out", &dir, "--set", "end_time=0.8"];
    second.extend(["--set", "pipeline.integrate.density_limit=0.02"]);
    second.extend(coarse);
    let o = engine(&second, &[]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("error: step ") && err.contains("stage `integrate`: density"),
        "{err}"
    );
    assert!(err.contains("(outputs written so far are kept in"), "{err}");
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let status = summary["status"].as_str().unwrap_or_default();
    assert!(
        status.starts_with("stopped at step") && status.contains("beyond rho_0 (1 +- 0.02)"),
        "{status}"
    );
    let vtp = std::fs::read_to_string(out.join("unstable.vtp")).expect("unstable.vtp");
    assert!(
        vtp.contains("NumberOfPoints=\"450\""),
        "unstable.vtp: {}",
        &vtp[..200]
    );
    // Each particle's id, and which guards have acted on it, to find it in ParaView.
    assert!(
        vtp.contains("Name=\"particle_id\"") && vtp.contains("Name=\"guarded\""),
        "unstable.vtp: {}",
        &vtp[..vtp.len().min(2000)]
    );
    for (f, bytes) in kept {
        assert!(
            std::fs::read(out.join(f)).unwrap() == bytes,
            "{f} changed under the failed run"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// A run killed (SIGKILL) while it writes checkpoints every few steps leaves a whole
/// checkpoint, from which `engine resume` finishes the run; a run killed that writes
/// no checkpoint leaves the folder's earlier checkpoints byte for byte.
#[test]
fn a_killed_run_leaves_whole_checkpoints_and_resumes() {
    let out = temp("killed");
    let dam = shipped("dam_break.ron").display().to_string();
    let dir = out.display().to_string();
    let coarse = coarse_dam("1");
    let spawn = |extra: &[&str]| {
        let mut args = vec![&dam[..], "--out", &dir, "--set", "end_time=1.5"];
        args.extend(extra);
        args.extend(coarse);
        Command::new(ENGINE)
            .args(&args)
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("the engine binary runs")
    };
    let checkpoint = out.join("checkpoint.bin");
    // Checkpoints every 0.01 s of simulated time (a few dozen steps): killed once the
    // third has been written, most likely in the middle of a step or a write.
    let mut child = spawn(&["--checkpoint-every", "0.01"]);
    let started = std::time::Instant::now();
    let mut seen = Vec::new();
    while seen.len() < 3 {
        assert!(
            started.elapsed().as_secs() < 60,
            "no checkpoints within a minute"
        );
        if let Ok(m) = std::fs::metadata(&checkpoint).and_then(|m| m.modified()) {
            if seen.last() != Some(&m) {
                seen.push(m);
            }
        }
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    child.kill().expect("kill");
    let status = child.wait().expect("wait");
    assert!(!status.success(), "the run ended before it was killed");
    let o = engine(&["resume", &dir, "--threads", "1", "-q"], &[]);
    assert!(o.status.success(), "resume after a kill: {}", stderr(&o));
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["status"], "completed", "{summary}");
    assert!((summary["simulated_time"].as_f64().unwrap() - 1.5).abs() < 1e-9);

    // A second run into the same folder, with no checkpoints of its own, killed.
    let kept: Vec<(&str, Vec<u8>)> = ["checkpoint.bin", "checkpoint.prev.bin"]
        .into_iter()
        .filter_map(|f| std::fs::read(out.join(f)).ok().map(|b| (f, b)))
        .collect();
    assert!(!kept.is_empty());
    let mut child = spawn(&[]);
    std::thread::sleep(std::time::Duration::from_millis(300));
    child.kill().expect("kill");
    let _ = child.wait();
    for (f, bytes) in kept {
        assert!(
            std::fs::read(out.join(f)).unwrap() == bytes,
            "{f} changed under the killed run"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

/// A full disk, as /dev/full stands for one: the run into a folder that holds an
/// earlier run's outputs and checkpoint stops with an error naming the file it could
/// not write and why, and exit code 1; the earlier checkpoint is left byte for byte.
#[cfg(target_os = "linux")]
#[test]
fn a_full_disk_stops_the_run_with_the_file_and_keeps_the_earlier_checkpoint() {
    let out = temp("full_disk");
    let dam = shipped("dam_break.ron").display().to_string();
    let dir = out.display().to_string();
    let run = |end: &str, extra: &[&str]| {
        let mut args = vec![&dam[..], "--out", &dir, "--set", end];
        args.extend(coarse_dam("1"));
        args.extend(extra);
        engine(&args, &[])
    };
    let o = run("end_time=0.2", &["--checkpoint-every", "0.1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let kept = std::fs::read(out.join("checkpoint.bin")).expect("checkpoint.bin");
    std::fs::remove_file(out.join("probes.csv")).unwrap();
    std::os::unix::fs::symlink("/dev/full", out.join("probes.csv")).unwrap();
    let o = run("end_time=0.3", &[]);
    let err = stderr(&o);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(
        err.contains("probes.csv") && err.contains("No space left on device"),
        "{err}"
    );
    assert!(
        std::fs::read(out.join("checkpoint.bin")).unwrap() == kept,
        "checkpoint.bin changed under the failed run"
    );
    let _ = std::fs::remove_dir_all(&out);
}
