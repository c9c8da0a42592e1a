//! A small study end to end (tests/scenarios/study_small.ron): the expected rows and
//! columns in study.csv, finite metrics, figures and report, resume skipping finished
//! cases, a stopped case as a row, and study-file errors with file:line:column.

use sph_scenario::overrides::Override;
use sph_study::study::{run_one_case, run_study, status, Study, StudyOptions};
use sph_tests::support::{read_csv, temp_out};
use std::path::{Path, PathBuf};

fn study_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/study_small.ron")
}

/// Width of a PNG from its header.
fn image_width(path: &Path) -> u32 {
    let bytes = std::fs::read(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    u32::from_be_bytes([bytes[16], bytes[17], bytes[18], bytes[19]])
}

fn load(sets: &[&str]) -> Study {
    let overrides: Vec<Override> = sets.iter().map(|s| s.parse().unwrap()).collect();
    Study::load(&study_file(), &overrides, &sph_stages::standard_registry())
        .unwrap_or_else(|e| panic!("{e}"))
}

fn run(study: &Study, out: &Path) -> Vec<sph_study::study::Row> {
    let opts = StudyOptions {
        workers: 2,
        threads: 1,
        report_only: false,
    };
    run_study(study, &sph_stages::standard_registry(), out, opts, &|_| ())
        .unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn small_study_writes_rows_metrics_figures_and_resumes() {
    let out = temp_out("study");
    let rows = run(&load(&[]), &out);
    assert_eq!(rows.len(), 2);
    assert!(rows.iter().all(|r| r.ran && r.completed()), "{rows:?}");

    let (header, table) = read_csv(&out.join("study.csv"));
    let names = [
        "case",
        "c0",
        "status",
        "wall_seconds",
        "particle_steps_per_second",
    ];
    for name in names.iter().chain(&[
        "surge_front_error",
        "P1.shepard_rms_error",
        "P1.shepard_peak_time",
        "P2_hydrostatic_error",
        "energy_loss_t0.2",
        "energy_loss_t0.5",
        "max_density_fluctuation",
        "spattered",
        "P1.shepard_total_variation",
        "neighbours_min",
        "neighbours_max",
        "lost",
    ]) {
        assert!(
            header.iter().any(|h| h == name),
            "no column {name} in {header:?}"
        );
    }
    assert_eq!(table.len(), 2);
    let status = header.iter().position(|h| h == "status").unwrap();
    for (row, c0) in table.iter().zip([20.0, 40.0]) {
        assert_eq!(row[1], c0);
        for (k, v) in row.iter().enumerate().skip(status + 1) {
            assert!(v.is_finite(), "{} = {v}", header[k]);
        }
    }
    // The surge front follows the data within the dam-break test's 10 %, energy is lost
    // and not gained, and no particle left the tank.
    for r in &rows {
        let m = |n: &str| r.metric(n).unwrap();
        assert!(
            m("surge_front_error") < 0.10,
            "{}: {}",
            r.case.name,
            m("surge_front_error")
        );
        assert!(m("energy_loss_t0.5") > m("energy_loss_t0.2") && m("energy_loss_t0.2") > 0.0);
        assert_eq!(m("lost"), 0.0);
        assert!(m("neighbours_max") > m("neighbours_min"));
    }
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("| c0_20.0 | 20.0 | completed |"),
        "{report}"
    );
    for figure in [
        "speed_vs_surge_front_error.png",
        "overlay1_kinetic_potential.png",
    ] {
        assert!(out.join(figure).is_file(), "{figure}");
        assert!(report.contains(figure));
    }
    // Both cases' snapshots side by side in one picture: two panels wide.
    assert!(report.contains("snapshots_t0.500.png"));
    let grid = image_width(&out.join("snapshots_t0.500.png"));
    assert_eq!(
        grid,
        2 * image_width(&out.join("c0_40.0/snapshot_t0.500.png"))
    );

    // Resume: nothing runs again, the same rows come back.
    let summary = out.join("c0_20.0/summary.json");
    let before = std::fs::metadata(&summary).unwrap().modified().unwrap();
    let again = run(&load(&[]), &out);
    assert!(again.iter().all(|r| !r.ran));
    assert_eq!(
        std::fs::metadata(&summary).unwrap().modified().unwrap(),
        before
    );
    assert_eq!(
        again[1].metric("spattered"),
        rows[1].metric("spattered"),
        "resumed metrics differ"
    );
    // A changed case (other overrides) runs again; the unchanged one does not.
    let changed = run(&load(&["pipeline.probe.interval=0.01"]), &out);
    assert!(changed.iter().all(|r| r.ran));
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn a_case_that_stops_early_is_a_row_with_its_reason() {
    let out = temp_out("study-stop");
    // A tight density guard stops the c0 = 20 m/s case within the first steps of the
    // collapse (densities near the wall leave +-1 %); the study still completes.
    let study = load(&["pipeline.integrate.density_limit=0.01", "end_time=0.1"]);
    let rows = run(&study, &out);
    assert_eq!(rows.len(), 2);
    let stopped: Vec<_> = rows.iter().filter(|r| !r.completed()).collect();
    assert!(!stopped.is_empty(), "{rows:?}");
    for r in stopped {
        assert!(r.status.starts_with("stopped at step"), "{}", r.status);
        assert!(r.metric("spattered").unwrap().is_nan());
    }
    let text = std::fs::read_to_string(out.join("study.csv")).unwrap();
    assert!(text.contains("stopped at step"));
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn study_file_errors_point_at_file_line_and_column() {
    let dir = temp_out("study-bad");
    std::fs::create_dir_all(&dir).unwrap();
    let registry = sph_stages::standard_registry();
    let write = |text: &str| {
        let path = dir.join("bad.ron");
        std::fs::write(&path, text).unwrap();
        Study::load(&path, &[], &registry).unwrap_err()
    };
    // An unknown field on line 3.
    let e = write("Study(\n    name: \"x\",\n    scenaro: \"a.ron\",\n    parameters: [],\n)\n");
    assert_eq!((e.line, e.column > 0), (3, true), "{e}");
    assert!(
        e.to_string().contains("bad.ron:3:") && e.to_string().contains("scenaro"),
        "{e}"
    );
    // A metric that does not exist, on line 6.
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/dam_break.ron");
    let head = format!(
        "Study(\n    name: \"x\",\n    scenario: {:?},\n    parameters: [(name: \"c\", path: \"fluid.sound_speed\", values: [\"20.0\"])],\n    metrics: [\n        Speed,\n    ],\n)\n",
        scenario.display().to_string()
    );
    let e = write(&head);
    assert_eq!(e.line, 6, "{e}");
    // A value the scenario refuses: the scenario loader's message, naming the case.
    let e = write(
        &head
            .replace("Speed,", "Lost,")
            .replace("\"20.0\"", "\"-1.0\""),
    );
    assert!(
        e.to_string().contains("case c_-1.0") && e.to_string().contains("sound_speed"),
        "{e}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn a_case_that_stops_early_runs_again_with_the_fallback_scheme() {
    let registry = sph_stages::standard_registry();
    let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("scenarios/study_fallback.ron");
    let study = Study::load(&file, &[], &registry).unwrap_or_else(|e| panic!("{e}"));
    let out = temp_out("study-fallback");
    let rows = run(&study, &out);
    // The guard of 0.1 % stops the paper's scheme; its fallback row follows it.
    let names: Vec<&str> = rows.iter().map(|r| r.case.name.as_str()).collect();
    assert_eq!(
        names,
        ["guard_0.5", "guard_0.001", "guard_0.001__fourtakas"],
        "{rows:?}"
    );
    assert!(rows[0].completed(), "{}", rows[0].status);
    assert!(
        rows[1].status.starts_with("stopped at step"),
        "{}",
        rows[1].status
    );
    assert!(rows[2].completed(), "{}", rows[2].status);
    assert!(rows.iter().all(|r| r.ran));

    let (header, _) = read_csv(&out.join("study.csv"));
    assert_eq!(
        header[..4],
        ["case", "guard", "scheme", "status"],
        "{header:?}"
    );
    let text = std::fs::read_to_string(out.join("study.csv")).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 4, "{text}");
    assert!(
        lines[1].starts_with("guard_0.5,0.5,paper,completed,"),
        "{text}"
    );
    assert!(
        lines[2].starts_with("guard_0.001,0.001,paper,\"stopped at step"),
        "{text}"
    );
    assert!(
        lines[3].starts_with("guard_0.001__fourtakas,0.001,fourtakas,completed,"),
        "{text}"
    );
    let fb = out.join("guard_0.001__fourtakas");
    let overrides = std::fs::read_to_string(fb.join("case.txt")).unwrap();
    assert!(
        overrides.ends_with(
            "pipeline.reinitialise.every=1000000000\npipeline.integrate.density_limit=0.5\n"
        ),
        "{overrides}"
    );
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    for said in [
        "1 of 2 cases completed with the `paper` scheme",
        "1 case(s) ran again with `fourtakas`, 1 of them completed",
        "Every case completed with one of the two schemes.",
        "| guard_0.001__fourtakas | 0.001 | fourtakas | completed |",
    ] {
        assert!(report.contains(said), "no `{said}` in\n{report}");
    }
    assert!(out.join("overlay1_kinetic_potential.png").is_file());

    // --status: the stopped case with its fallback run under it (2+), nothing pending.
    let states = status::study_status(&study, &out);
    let fallbacks = status::fallback_status(&study, &out, &states);
    assert_eq!(fallbacks.len(), 1);
    assert_eq!((fallbacks[0].0, fallbacks[0].1.name()), (2, "finished"));
    let table = status::status_table(&study, &states, &fallbacks);
    assert!(
        table.contains("  2+  guard_0.001__fourtakas  finished"),
        "{table}"
    );
    assert!(
        table.contains("1 fallback run(s) with `fourtakas`"),
        "{table}"
    );
    assert!(status::pending_cases(&study, &out).is_empty());

    // A rerun skips every finished run, the fallback's too, and gives the same rows.
    let summary = fb.join("summary.json");
    let before = std::fs::metadata(&summary).unwrap().modified().unwrap();
    let again = run(&study, &out);
    assert_eq!(again.len(), 3);
    assert!(again.iter().all(|r| !r.ran), "{again:?}");
    assert_eq!(
        std::fs::metadata(&summary).unwrap().modified().unwrap(),
        before
    );
    assert_eq!(
        std::fs::read_to_string(out.join("study.csv")).unwrap(),
        text
    );

    // Without its fallback run, case 2 is pending; `--case 2` (run_one_case) skips the
    // finished paper run and runs the fallback.
    std::fs::remove_dir_all(&fb).unwrap();
    assert_eq!(status::pending_cases(&study, &out), [2]);
    let one = run_one_case(&study, 1, &out, 1, &registry).unwrap_or_else(|e| panic!("{e}"));
    let said: Vec<(bool, &str, &str)> = one
        .iter()
        .map(|(ran, r)| {
            (
                *ran,
                r.case.name.as_str(),
                r.case.scheme.as_deref().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        said,
        [
            (false, "guard_0.001", "paper"),
            (true, "guard_0.001__fourtakas", "fourtakas")
        ]
    );
    assert!(one[1].1.completed());
    // Case 1 completed: no fallback run.
    let one = run_one_case(&study, 0, &out, 1, &registry).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(one.len(), 1);
    assert!(!one[0].0);
    // A report of a folder without case 1: named as not run, not as failed.
    std::fs::remove_dir_all(out.join("guard_0.5")).unwrap();
    let opts = StudyOptions {
        workers: 1,
        threads: 1,
        report_only: true,
    };
    run_study(&study, &registry, &out, opts, &|_| ()).unwrap_or_else(|e| panic!("{e}"));
    let report = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(
        report.contains("Completed by neither scheme: guard_0.5 (not run)."),
        "{report}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn fallback_errors_point_at_the_study_file() {
    let dir = temp_out("study-bad-fallback");
    std::fs::create_dir_all(&dir).unwrap();
    let registry = sph_stages::standard_registry();
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/dam_break_paper.ron");
    let write = |fallback: &str| {
        let path = dir.join("bad.ron");
        let text = format!(
            "Study(\n    name: \"x\",\n    scenario: {:?},\n    parameters: [(name: \"c\", path: \"fluid.sound_speed\", values: [\"20.0\"])],\n    fallback: {fallback},\n)\n",
            scenario.display().to_string()
        );
        std::fs::write(&path, text).unwrap();
        Study::load(&path, &[], &registry).unwrap_err().to_string()
    };
    // An override without `=`: the entry's line and column.
    let e = write("(label: \"f\", set: [\"end_time\"])");
    assert!(
        e.contains("bad.ron:5:34") && e.contains("fallback.set"),
        "{e}"
    );
    // A path the scenario does not have: the scenario loader's message, naming the case.
    let e = write("(label: \"f\", set: [\"pipeline.nothing.every=1\"])");
    assert!(
        e.contains("bad.ron:5:5") && e.contains("the fallback of case c_20.0__f"),
        "{e}"
    );
    // A label that cannot be a folder suffix, no overrides, an unknown field.
    let e = write("(label: \"a b\", set: [\"end_time=1.0\"])");
    assert!(
        e.contains("bad.ron:5:23") && e.contains("fallback.label"),
        "{e}"
    );
    let e = write("(label: \"f\", set: [])");
    assert!(
        e.contains("bad.ron:5:5") && e.contains("fallback.set"),
        "{e}"
    );
    let e = write("(label: \"f\", sets: [])");
    assert!(e.contains("bad.ron:5:") && e.contains("sets"), "{e}");
    let _ = std::fs::remove_dir_all(&dir);
}

/// Every study shipped in scenarios/studies/ loads: its file parses, and every case's
/// and fallback's scenario loads with the case's overrides (`Study::load` loads them
/// all), so a shipped study cannot fail at its first case on a renamed field or path.
#[test]
fn every_shipped_study_loads_with_all_its_cases() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("../scenarios/studies");
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "ron"))
        .collect();
    files.sort();
    // The six dam-break studies, the density treatment and the three sloshing studies.
    assert!(files.len() >= 11, "{files:?}");
    for f in &files {
        let study = Study::load(f, &[], &sph_stages::standard_registry())
            .unwrap_or_else(|e| panic!("{}: {e}", f.display()));
        assert!(!study.cases.is_empty(), "{}", f.display());
    }
}
