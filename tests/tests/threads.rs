//! A run's results do not depend on the number of worker threads: a small dam break
//! and a small rolling tank, each on one thread and on two, write byte-identical
//! probes.csv and energy.csv.

use sph_core::overrides::Override;
use sph_core::runner::{run, RunOptions};
use sph_core::Scenario;
use sph_tests::support::temp_out;
use std::path::PathBuf;

const DAM: &str = include_str!("../../scenarios/dam_break.ron");
const SLOSHING: &str = include_str!("../../scenarios/sloshing.ron");

/// Keep output cheap: one frame, no pictures or plots.
const QUIET: [&str; 4] = [
    "pipeline.vtk_frames.interval=1.0",
    "pipeline.snapshots.times=[]",
    "pipeline.probe.plots=false",
    "pipeline.energy.plots=false",
];

/// Runs a small version of `text` on `threads` threads; returns the output folder.
fn run_on(text: &str, file: &str, coarse: &[&str], threads: usize) -> PathBuf {
    let overrides: Vec<Override> = coarse
        .iter()
        .chain(&QUIET)
        .map(|o| o.parse().unwrap_or_else(|e| panic!("{e}")))
        .collect();
    let registry = sph_stages::standard_registry();
    let scenario =
        Scenario::from_str(text, file, &overrides, &registry).unwrap_or_else(|e| panic!("{e}"));
    let out = temp_out(&format!("threads{threads}"));
    let opts = RunOptions {
        out_dir: out.clone(),
        threads: Some(threads),
        progress: false,
        trace: None,
        ..Default::default()
    };
    let summary = run(scenario, &opts).unwrap_or_else(|e| panic!("{threads} threads: {e}"));
    assert_eq!(summary.status, "completed");
    assert_eq!(summary.threads, threads);
    assert!(summary.steps > 100, "{} steps", summary.steps);
    out
}

#[test]
fn dam_break_does_not_depend_on_thread_count() {
    let coarse = ["resolution=ParticlesAcross(40)", "end_time=0.3"];
    let file = "scenarios/dam_break.ron";
    compare(run_on(DAM, file, &coarse, 1), run_on(DAM, file, &coarse, 2));
}

#[test]
fn rolling_tank_does_not_depend_on_thread_count() {
    // Moving walls, tank-frame sensors and the roll moment sum.
    let coarse = [
        "resolution=ParticlesAcross(60)",
        "end_time=0.4",
        "tank.motion.ramp=0.1",
    ];
    let file = "scenarios/sloshing.ron";
    compare(
        run_on(SLOSHING, file, &coarse, 1),
        run_on(SLOSHING, file, &coarse, 2),
    );
}

fn compare(one: PathBuf, two: PathBuf) {
    for file in ["probes.csv", "energy.csv"] {
        let read = |dir: &PathBuf| {
            std::fs::read_to_string(dir.join(file))
                .unwrap_or_else(|e| panic!("{}: {e}", dir.join(file).display()))
        };
        let (a, b) = (read(&one), read(&two));
        assert!(a.lines().count() > 10, "{file} has rows:\n{a}");
        if a != b {
            let (n, (la, lb)) = a
                .lines()
                .zip(b.lines())
                .enumerate()
                .find(|(_, (la, lb))| la != lb)
                .unwrap_or((0, ("(length differs)", "")));
            panic!(
                "{file} differs between 1 and 2 threads, first at line {}:\n  1: {la}\n  2: {lb}\n(outputs kept in {} and {})",
                n + 1,
                one.display(),
                two.display()
            );
        }
    }
    for dir in [one, two] {
        let _ = std::fs::remove_dir_all(dir);
    }
}
