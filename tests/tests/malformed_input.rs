//! Every way a scenario can be wrong must give an error (never a panic) whose message
//! says what is wrong and what would be accepted, and — when the error is tied to a
//! place in the file — whose line points at the offending line.
//!
//! One table-driven test: each case is a scenario text (usually a one-line mutation of
//! the shipped `scenarios/dam_break_paper.ron`), `--set` overrides, where the error must
//! point, the field it must name and substrings its message must hold. Expected line
//! numbers are computed from the constructed text (the line holding a marker string),
//! and the mutations find fields and stages by name, so the table stays right when the
//! shipped scenario is edited.

use sph_scenario::overrides::Override;
use sph_scenario::{LoadError, Scenario};
use std::time::{Duration, Instant};

#[path = "malformed_input/cases.rs"]
mod cases;
#[path = "malformed_input/set_cases.rs"]
mod set_cases;

use cases::*;

/// What is wrong with `err` as the error for `case` (empty: nothing).
fn problems(case: &Case, file: &str, err: &LoadError) -> Vec<String> {
    let shown = err.to_string();
    let mut problems = Vec::new();
    if err.file != file || !shown.starts_with(file) {
        problems.push(format!("does not start with the file name `{file}`"));
    }
    for s in case.expect {
        if !shown.contains(s) {
            problems.push(format!("lacks `{s}`"));
        }
    }
    let field = err.field.as_deref();
    let field_ok = match case.field {
        Field::Any => true,
        Field::Is(f) => field == Some(f),
        Field::AbsentOr(fs) => field.is_none_or(|f| fs.contains(&f)),
    };
    if !field_ok {
        problems.push(format!("field is {field:?}, expected {:?}", case.field));
    }
    let line = match case.place {
        Place::LineOf(marker) => line_of(&case.text, marker),
        Place::LastLine => case.text.lines().count().max(1),
        Place::Nowhere => 0,
    };
    if err.line != line {
        problems.push(format!("line {}, expected {line}", err.line));
    } else if line == 0 {
        if err.column != 0 {
            problems.push(format!("column {} without a line", err.column));
        }
    } else {
        let width = case
            .text
            .lines()
            .nth(line - 1)
            .unwrap_or("")
            .chars()
            .count();
        if err.column == 0 || err.column > width + 1 {
            problems.push(format!("column {} is not on line {line}", err.column));
        } else if !shown.starts_with(&format!("{file}:{line}:{}: ", err.column)) {
            problems.push("Display does not start with `file:line:column: `".into());
        }
    }
    problems
}

#[test]
fn malformed_scenarios_give_located_errors() {
    let registry = sph_stages::standard_registry();
    let mut failures = Vec::new();
    let mut gaps = Vec::new();
    for case in cases() {
        let file = format!("{}.ron", case.name.replace([' ', ':'], "_"));
        let overrides: Vec<Override> = case
            .overrides
            .iter()
            .map(|o| o.parse().expect("the case's override parses"))
            .collect();
        let start = Instant::now();
        let result = Scenario::from_str(&case.text, &file, &overrides, &registry);
        // Every case is refused from the text and the numbers alone, before any
        // particle is allocated, so quickly.
        let elapsed = start.elapsed();
        let err = match result {
            Ok(_) => {
                failures.push(format!("{}: loaded without error", case.name));
                continue;
            }
            Err(e) => e,
        };
        let shown = err.to_string();
        println!("{:<30} {shown}", case.name);
        let mut found = problems(&case, &file, &err);
        if elapsed > Duration::from_secs(2) {
            found.push(format!("took {elapsed:?}"));
        }
        let report = format!("{}: {}\n    got: {shown}", case.name, found.join("; "));
        match (case.expect_known_gap, found.is_empty()) {
            (false, true) => {}
            (false, false) => failures.push(report),
            (true, false) => gaps.push(report),
            (true, true) => gaps.push(format!(
                "{}: now passes; remove its `expect_known_gap`",
                case.name
            )),
        }
    }
    if !gaps.is_empty() {
        println!("\nknown gaps (not enforced):\n{}", gaps.join("\n"));
    }
    assert!(
        failures.is_empty(),
        "{} case(s) failed:\n{}",
        failures.len(),
        failures.join("\n")
    );
}

/// An error in the file on the line an override patched keeps the file's line and
/// column: the override's text is taken back out of the position.
#[test]
fn file_errors_beside_overrides_keep_their_place_in_the_file() {
    let registry = sph_stages::standard_registry();
    let text = DAM.replacen(
        "Reinitialise(every: 1",
        "Reinitialise(every: 1, bogus: 2",
        1,
    );
    assert_ne!(text, DAM, "dam_break_paper.ron has `Reinitialise(every: 1`");
    let load = |sets: &[&str]| {
        let overrides: Vec<Override> = sets.iter().map(|s| s.parse().unwrap()).collect();
        Scenario::from_str(&text, "dam.ron", &overrides, &registry).expect_err("bogus field")
    };
    let plain = load(&[]);
    assert!(plain.line > 0 && plain.set.is_none(), "{plain}");
    for sets in [
        &["pipeline.reinitialise.every=100000"][..],
        &[
            "pipeline.reinitialise.filter=Shepard",
            "end_time=2.000000000",
        ],
        &["pipeline.0=GhostWalls(slip: FreeSlip, hydrostatic: true)"],
    ] {
        let e = load(sets);
        assert_eq!(
            (e.line, e.column, e.set.as_deref()),
            (plain.line, plain.column, None),
            "with --set {sets:?}: {e}"
        );
        assert!(e.message.contains("`bogus`"), "{e}");
    }
}

/// The example in the message for a malformed `--set` names a real stage and field:
/// it applies to the shipped dam break and loads.
#[test]
fn set_usage_example_applies_to_a_shipped_scenario() {
    let e = "pipeline".parse::<Override>().unwrap_err().to_string();
    assert!(
        e.starts_with("--set pipeline: expected `path=value`"),
        "{e}"
    );
    let examples: Vec<&str> = e.split('`').skip(1).step_by(2).skip(1).collect();
    assert!(examples.contains(&"pipeline.reinitialise.every=5"), "{e}");
    let registry = sph_stages::standard_registry();
    for example in examples {
        let ov: Override = example.parse().unwrap();
        if let Err(e) = Scenario::from_str(DAM, "dam_break_paper.ron", &[ov], &registry) {
            panic!("the example `{example}` does not load: {e}");
        }
    }
}
