//! The `engine` command's progress output, run as a user runs it: the binary with
//! its stderr piped (not a terminal).

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
