//! A small study end to end (tests/scenarios/study_small.ron): the expected rows and
//! columns in study.csv, finite metrics, figures and report, resume skipping finished
//! cases, a stopped case as a row, and study-file errors with file:line:column.

use sph_scenario::overrides::Override;
use sph_study::study::{run_study, Study, StudyOptions};
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
