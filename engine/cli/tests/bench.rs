//! `engine bench` end to end at the smallest size: each case runs in a child process and
//! lands as a row of bench.csv with a measured speed. (A fixed-step run once failed the
//! engine's size limits through its unbounded end time; nothing else ran the harness.)

use std::path::Path;
use std::process::Command;

#[test]
fn bench_writes_a_row_per_case() {
    let out = std::env::temp_dir().join(format!("engine-bench-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let scenario = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scenarios/dam_break.ron");
    let status = Command::new(env!("CARGO_BIN_EXE_engine"))
        .args([
            "bench",
            "--sizes",
            "800",
            "--threads",
            "1,2",
            "--steps",
            "5",
        ])
        .args(["--time-sizes", "none", "--scenario"])
        .arg(&scenario)
        .arg("--out")
        .arg(&out)
        .status()
        .unwrap();
    assert!(status.success(), "engine bench exited with {status}");
    let csv = std::fs::read_to_string(out.join("bench.csv")).unwrap();
    let rows: Vec<&str> = csv.lines().skip(1).collect();
    assert_eq!(rows.len(), 2, "{csv}");
    for row in rows {
        let cells: Vec<&str> = row.split(',').collect();
        assert_eq!(cells[0], "steps", "{row}");
        assert_eq!(cells[3], "5", "{row}");
        let speed: f64 = cells[6].parse().unwrap();
        assert!(speed.is_finite() && speed > 0.0, "{row}");
    }
    let _ = std::fs::remove_dir_all(&out);
}
