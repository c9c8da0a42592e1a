//! Ctrl-C: SIGINT to a running `engine` writes a checkpoint and exits with code 130;
//! `engine resume` then continues, and the probes match a run stopped at the same time
//! without the interruption.

#![cfg(unix)]

use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::time::{Duration, Instant};

const ENGINE: &str = env!("CARGO_BIN_EXE_engine");

fn scenario() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/wave_maker.ron")
}

fn temp(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("engine-interrupt-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Coarse and cheap; end_time far away so that only the signal stops the run.
const SETS: [&str; 8] = [
    "--set",
    "resolution=Spacing(0.08)",
    "--set",
    "pipeline.probe.plots=false",
    "--set",
    "pipeline.energy.plots=false",
    "--set",
    "pipeline.vtk_frames.interval=1.0",
];

fn engine(args: &[&str]) -> Command {
    let mut c = Command::new(ENGINE);
    c.args(args).args(["-q", "--threads", "1"]);
    c
}

/// Starts `engine ARGS`, waits until its run has started (the signal handler is
/// installed before the stages' setup, which creates probes.csv in `out`) and a little
/// more, sends `signal` with `kill`, and returns the exit status.
fn signal_once_started(args: &[&str], out: &Path, signal: &str) -> ExitStatus {
    let mut child = engine(args).spawn().unwrap();
    let start = Instant::now();
    while !out.join("probes.csv").exists() {
        assert!(
            start.elapsed() < Duration::from_secs(60),
            "the run never started"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    std::thread::sleep(Duration::from_millis(200));
    let killed = Command::new("kill")
        .args([signal, &child.id().to_string()])
        .status()
        .unwrap();
    assert!(killed.success());
    child.wait().unwrap()
}

#[test]
fn sigint_writes_a_checkpoint_and_resume_continues() {
    let (out, reference) = (temp("run"), temp("reference"));
    let out_s = out.to_str().unwrap();
    let scene = scenario();
    let scene = scene.to_str().unwrap();
    let mut args = vec![scene, "--out", out_s, "--set", "end_time=500.0"];
    args.extend(SETS);
    let status = signal_once_started(&args, &out, "-INT");
    assert_eq!(status.code(), Some(130), "exit code after Ctrl-C");
    let summary = std::fs::read_to_string(out.join("summary.json")).unwrap();
    assert!(summary.contains("interrupted at step"), "{summary}");
    let (checkpoint, notes) = sph_core::checkpoint::read_latest(&out).unwrap();
    assert!(notes.is_empty(), "{notes:?}");

    // Resume for 0.2 s more, and compare with a run stopped there uninterrupted.
    let stop = format!("{}", checkpoint.time + 0.2);
    let resumed = engine(&["resume", out_s, "--stop-at", &stop])
        .output()
        .unwrap();
    assert!(
        resumed.status.success(),
        "{}",
        String::from_utf8_lossy(&resumed.stderr)
    );
    let reference_s = reference.to_str().unwrap();
    let mut args = vec![scene, "--out", reference_s, "--set", "end_time=500.0"];
    args.extend(SETS);
    args.extend(["--stop-at", &stop]);
    let plain = engine(&args).output().unwrap();
    assert!(
        plain.status.success(),
        "{}",
        String::from_utf8_lossy(&plain.stderr)
    );
    for f in ["probes.csv", "energy.csv"] {
        let a = std::fs::read(out.join(f)).unwrap();
        let b = std::fs::read(reference.join(f)).unwrap();
        assert!(a == b, "{f} differs after the interruption");
    }
    for dir in [out, reference] {
        let _ = std::fs::remove_dir_all(dir);
    }
}

#[test]
fn sigterm_also_checkpoints() {
    let out = temp("term");
    let out_s = out.to_str().unwrap();
    let scene = scenario();
    let mut args = vec![
        scene.to_str().unwrap(),
        "--out",
        out_s,
        "--set",
        "end_time=500.0",
    ];
    args.extend(SETS);
    let status = signal_once_started(&args, &out, "-TERM");
    assert_eq!(status.code(), Some(130), "exit code after SIGTERM");
    assert!(sph_core::checkpoint::read_latest(&out).is_ok());
    let _ = std::fs::remove_dir_all(out);
}
