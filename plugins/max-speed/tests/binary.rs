//! The plugin's binary is the whole `engine` command with `MaxSpeed` registered: it
//! lists the stage and runs the plugin's scenario, which the stock `engine` refuses.

use std::process::Command;

const BIN: &str = env!("CARGO_BIN_EXE_max-speed");
const SCENARIO: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/max_speed.ron");

#[test]
fn the_binary_lists_and_runs_the_plugin_stage() {
    let stages = Command::new(BIN).arg("stages").output().expect("runs");
    let listed = String::from_utf8_lossy(&stages.stdout);
    assert!(stages.status.success(), "{listed}");
    assert!(listed.contains("MaxSpeed"), "{listed}");
    assert!(listed.contains("Forces"), "{listed}");

    let out = std::env::temp_dir().join(format!("max-speed-bin-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let run = Command::new(BIN)
        .arg(SCENARIO)
        .args(["-q", "--threads", "1", "--out"])
        .arg(&out)
        .output()
        .expect("runs");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    let csv = std::fs::read_to_string(out.join(max_speed::CSV)).expect("max_speed.csv");
    assert!(
        csv.starts_with("time,max_speed\n") && csv.lines().count() > 3,
        "{csv}"
    );
    let _ = std::fs::remove_dir_all(&out);
}
