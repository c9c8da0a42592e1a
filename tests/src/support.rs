//! Helpers shared by the integration tests: scenario loading with overrides, runs into
//! fresh temporary folders, and CSV reading for outputs and reference data.

use sph_core::Sim;
use sph_run::runner::{run_keeping_state, RunOptions, Summary};
use sph_scenario::overrides::Override;
use sph_scenario::Scenario;
use std::path::{Path, PathBuf};

/// A fresh, empty output folder under the system temp folder, named by the tag, the
/// process, the time and a count of the folders this process has asked for (two tests
/// running the same tagged case at once can read the same clock).
pub fn temp_out(tag: &str) -> PathBuf {
    static COUNT: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);
    let k = COUNT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let dir = std::env::temp_dir().join(format!(
        "sph-tests-{tag}-{}-{nanos}-{k}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// Loads scenario text with `--set`-style overrides and the standard stages; panics
/// with the loader's message on error.
pub fn load(text: &str, file: &str, overrides: &[&str]) -> Scenario {
    let overrides: Vec<Override> = overrides
        .iter()
        .map(|o| o.parse().unwrap_or_else(|e| panic!("{e}")))
        .collect();
    Scenario::from_str(text, file, &overrides, &sph_stages::standard_registry())
        .unwrap_or_else(|e| panic!("{e}"))
}

/// Runs to completion on `threads` threads into a fresh folder; returns the summary,
/// the final state and the folder.
pub fn run_completed(scenario: Scenario, tag: &str, threads: usize) -> (Summary, Sim, PathBuf) {
    let out = temp_out(tag);
    let opts = RunOptions::quiet(&out, threads);
    let (summary, sim) =
        run_keeping_state(scenario, &opts).unwrap_or_else(|e| panic!("{tag}: {e}"));
    assert_eq!(summary.status, "completed");
    (summary, sim, out)
}

/// Numeric rows of a CSV file, skipping `#` comment lines; returns (header, rows)
/// ([`sph_study::series::read_table`], panicking on error).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    sph_study::series::read_table(path).unwrap_or_else(|e| panic!("{e}"))
}

/// Column `name` of a CSV against its first column.
pub fn series(path: &Path, name: &str) -> Vec<(f64, f64)> {
    let (header, rows) = read_csv(path);
    let k = header
        .iter()
        .position(|h| h == name)
        .unwrap_or_else(|| panic!("no column {name} in {}", path.display()));
    rows.iter().map(|r| (r[0], r[k])).collect()
}

pub use sph_core::extremes::{nan_max, nan_min};

/// Reference data shipped in tests/data, sorted by its first column.
pub fn reference(file: &str) -> Vec<(f64, f64)> {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("data")
        .join(file);
    let (_, rows) = read_csv(&path);
    let mut points: Vec<(f64, f64)> = rows.iter().map(|r| (r[0], r[1])).collect();
    points.sort_by(|a, b| a.0.total_cmp(&b.0));
    points
}

/// Linear interpolation of a time series at `t` (clamped at the ends).
pub use sph_study::study::metrics::interpolate;

/// The surge front of a run of Martin & Moyce's column (width `a` [m]) in their
/// normalisation, (T, Z) = (t sqrt(2g/a), x/a), from the run's `probes.csv`; asserts
/// that the front never moves back.
pub fn surge_front(out: &Path, a: f64) -> Vec<(f64, f64)> {
    let scale = (2.0 * 9.81 / a).sqrt();
    let front: Vec<(f64, f64)> = series(&out.join("probes.csv"), "front")
        .iter()
        .map(|&(t, x)| (t * scale, x / a))
        .collect();
    assert!(
        front.windows(2).all(|w| w[1].1 >= w[0].1 - 1e-9),
        "front moved back"
    );
    front
}

/// Asserts that no particle was reflected back through a wall during the run (and so
/// none crossed one: without the reflection the run would have stopped).
pub fn assert_no_wall_reflections(summary: &Summary) {
    assert_eq!(
        summary.diagnostics.get("wall_reflections"),
        None,
        "{:?}",
        summary.diagnostics
    );
}
