//! The profile comes from the spans: with `RunOptions::profile` the per-stage calls and
//! seconds of `summary.json` and the `--profile` table are the runner's `stage` spans,
//! with the stages' inner spans under them; `--trace` writes the same spans, and both
//! can be on together. Without the profiler, the summary has no stage times.

use sph_run::runner::{run, RunOptions, StageTime};
use sph_tests::support::{load, temp_out};

const DAM: &str = include_str!("../../scenarios/dam_break_paper.ron");

/// A coarse dam break with `Reinitialise()` twice (two Shepard filters in a row: a
/// second updater of the density is allowed), for a few steps.
fn scenario() -> sph_scenario::Scenario {
    let text = DAM.replacen(
        "Reinitialise(every: 1),",
        "Reinitialise(every: 1), Reinitialise(every: 1),",
        1,
    );
    assert_ne!(
        text, DAM,
        "dam_break_paper.ron lost its `Reinitialise(every: 1),`"
    );
    load(
        &text,
        "dam_break_paper.ron",
        &[
            "resolution=ParticlesAcross(20)",
            "end_time=0.05",
            // Lists rebuilt every step, so the grid's inner spans run every step.
            "pipeline.neighbour_grid.skin=0",
            "pipeline.probe.plots=false",
            "pipeline.energy.plots=false",
            "pipeline.snapshots.times=[]",
        ],
    )
}

fn stage<'a>(stages: &'a [StageTime], name: &str) -> &'a StageTime {
    stages
        .iter()
        .find(|s| s.stage == name)
        .unwrap_or_else(|| panic!("no stage `{name}` in {stages:?}"))
}

/// A profiled and traced run, beside an unprofiled one on another thread (which must
/// not switch the spans off for the first: tokio-rs/tracing#3611).
#[test]
fn stage_times_and_inner_spans_come_from_the_spans() {
    let out = temp_out("profile");
    let trace = out.with_extension("trace.json");
    let opts = RunOptions {
        profile: true,
        trace: Some(trace.clone()),
        ..RunOptions::quiet(&out, 2)
    };
    let plain = temp_out("unprofiled");
    let (summary, unprofiled) = std::thread::scope(|s| {
        let other = s.spawn(|| run(scenario(), &RunOptions::quiet(&plain, 1)));
        let summary = run(scenario(), &opts).unwrap_or_else(|e| panic!("{e}"));
        (
            summary,
            other
                .join()
                .expect("no panic")
                .unwrap_or_else(|e| panic!("{e}")),
        )
    });
    // Without the profiler, the summary has no stage times.
    assert!(unprofiled.steps > 0);
    assert!(unprofiled.stages.is_empty(), "{:?}", unprofiled.stages);
    assert_eq!(unprofiled.profiled_steps, 0);
    let _ = std::fs::remove_dir_all(&plain);

    let steps = summary.steps;
    assert!(
        steps > 20,
        "{steps} steps: too few to see the sort's period"
    );
    assert_eq!(summary.profiled_steps, steps);
    let names: Vec<&str> = summary.stages.iter().map(|s| s.stage.as_str()).collect();
    assert_eq!(names.len(), 11, "{names:?}");
    assert_eq!(names.iter().filter(|n| **n == "reinitialise").count(), 2);

    // Every stage of every step, each Reinitialise entry on its own row.
    for s in &summary.stages {
        assert_eq!(s.calls, steps, "{}", s.stage);
        assert!(s.seconds > 0.0, "{}", s.stage);
    }
    let grid = stage(&summary.stages, "neighbour_grid");
    let inner = |name: &str| {
        grid.inner
            .iter()
            .find(|s| s.span == name)
            .unwrap_or_else(|| panic!("no `{name}` under neighbour_grid: {:?}", grid.inner))
    };
    assert_eq!(inner("grid_build").calls, steps);
    assert_eq!(inner("scan").calls, steps);
    // The cell sort every 20 calls, from the first.
    assert_eq!(inner("sort").calls, steps.div_ceil(20));
    let nested: f64 = grid.inner.iter().map(|s| s.seconds).sum();
    assert!(nested > 0.0 && nested <= grid.seconds, "{grid:?}");
    let mirror = stage(&summary.stages, "ghost_walls").inner.iter();
    assert!(mirror
        .map(|s| s.span.as_str())
        .eq(["find_images", "mirror"]));

    // The table: the stages and, indented under neighbour_grid, its spans.
    let table = summary.profile_table();
    let lines: Vec<&str> = table.lines().collect();
    let at = |label: &str| {
        lines
            .iter()
            .position(|l| l.split_whitespace().next() == Some(label))
            .unwrap_or_else(|| panic!("no row `{label}` in\n{table}"))
    };
    let (g, b) = (at("neighbour_grid"), at("grid_build"));
    assert!(b > g && lines[b].starts_with("  grid_build"), "{table}");
    assert!(
        lines[b].split_whitespace().nth(1) == Some(&steps.to_string()),
        "{table}"
    );
    let total = lines.last().expect("a total row");
    assert!(
        total.starts_with("total") && total.contains(&steps.to_string()),
        "{table}"
    );

    // summary.json: the same numbers, field names as before.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("summary.json")).unwrap()).unwrap();
    let rows = json["stages"].as_array().expect("stages");
    let row = rows
        .iter()
        .find(|r| r["stage"] == "neighbour_grid")
        .unwrap();
    assert_eq!(row["calls"], steps);
    assert_eq!(row["seconds"].as_f64(), Some(grid.seconds));
    assert!(row["inner"]
        .as_array()
        .is_some_and(|i| i.iter().any(|s| s["span"] == "scan")));

    // The trace holds the same spans, as complete JSON.
    let written: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&trace).unwrap()).expect("trace JSON");
    let events = written.as_array().expect("a JSON array of events");
    for name in ["step", "stage", "grid_build", "scan", "find_images"] {
        assert!(
            events.iter().any(|e| e["name"] == name),
            "no `{name}` in the trace"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
    let _ = std::fs::remove_file(&trace);
}
