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
            "--isa",
            "scalar",
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
        // The child ran the instruction set asked for.
        assert_eq!(cells[16], "scalar", "{row}");
    }
    let md = std::fs::read_to_string(out.join("bench.md")).unwrap();
    assert!(
        md.contains("Machine: ") && md.contains("| scalar |"),
        "{md}"
    );
    let _ = std::fs::remove_dir_all(&out);
}

/// An instruction set the processor lacks, or a made-up one, is refused before any run,
/// with what is accepted.
#[test]
fn bench_refuses_an_unknown_instruction_set() {
    let out = std::env::temp_dir().join(format!("engine-bench-isa-{}", std::process::id()));
    let output = Command::new(env!("CARGO_BIN_EXE_engine"))
        .args(["bench", "--sizes", "800", "--isa", "avx9", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    assert!(!output.status.success());
    let err = String::from_utf8_lossy(&output.stderr);
    assert!(
        err.contains("--isa") && err.contains("`avx9`") && err.contains("accepted: auto"),
        "{err}"
    );
    assert!(!out.join("bench.csv").exists());
    let _ = std::fs::remove_dir_all(&out);
}
