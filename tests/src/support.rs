//! Helpers shared by the integration tests: scenario loading with overrides, runs into
//! fresh temporary folders, and CSV reading for outputs and reference data.

use sph_core::overrides::Override;
use sph_core::runner::{run_keeping_state, RunOptions, Summary};
use sph_core::{Scenario, Sim};
use std::path::{Path, PathBuf};

/// A fresh, empty output folder under the system temp folder.
pub fn temp_out(tag: &str) -> PathBuf {
    let nanos = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let dir = std::env::temp_dir().join(format!("sph-tests-{tag}-{}-{nanos}", std::process::id()));
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
/// ([`sph_core::series::read_table`], panicking on error).
pub fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<f64>>) {
    sph_core::series::read_table(path).unwrap_or_else(|e| panic!("{e}"))
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
pub use sph_core::study::metrics::interpolate;
