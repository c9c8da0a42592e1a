//! Sensitivity studies (`engine study scenarios/studies/<name>.ron`): a base scenario,
//! parameters to vary and metrics to report. Every case is a run of the base scenario
//! with `--set` overrides ([`sph_scenario::overrides`]); cases run side by side, one thread
//! each ([`crate::parallel`]), into `<out>/<case>/`, and a case whose folder already
//! holds its finished run (same overrides, `summary.json` written) is not run again,
//! so an interrupted study resumes. The study writes `study.csv` (one row per case:
//! parameters, status, wall seconds, steps, particle-steps per second, every metric),
//! figures ([`figures`]) and `report.md`.
//!
//! A case that stops early (e.g. the density guard) is a row with its stop reason and
//! the metrics of the part it ran, not a failure of the study. A study with a
//! [`Fallback`] then runs that case again with the fallback's overrides appended, into
//! `<out>/<case>__<label>/`, as a row right after the case's; the `scheme` column says
//! which scheme each row used.

pub mod figures;
pub mod metrics;
pub mod status;

mod spec;
pub use spec::*;
mod cases;
pub use cases::*;
mod run;
pub use run::*;
mod evaluate;
pub use evaluate::*;
mod report;
pub use report::*;

use crate::series::read_series;
use crate::StudyError;
use glam::DVec2;
use serde::Deserialize;
use sph_core::StageRegistry;
use sph_run::runner::{run_keeping_state, RunError, RunOptions};
use sph_scenario::overrides::Override;
use sph_scenario::scenario::{parse_ron, LoadError};
use sph_scenario::Scenario;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(design: &str, linked: &str) -> StudySpec {
        parse_ron(
            &format!(
                r#"Study(name: "s", scenario: "x.ron", design: {design}, set: ["end_time=1.0"],
                    parameters: [
                        (name: "c0", path: "fluid.sound_speed", values: ["12.0", "25.0", "50.0"]),
                        (name: "k", path: "kernel", values: ["Cubic", "Gaussian"], labels: ["cubic", "gauss"],
                         linked: [(path: "h_over_dx", values: [{linked}])]),
                    ])"#
            ),
            "s.ron",
        )
        .unwrap_or_else(|e| panic!("{e}"))
    }

    #[test]
    fn one_at_a_time_varies_each_parameter_from_the_base_case() {
        let cases = cases(&spec("OneAtATime", r#""1.3", "0.9""#), "s.ron", &[]).unwrap();
        let names: Vec<&str> = cases.iter().map(|c| c.name.as_str()).collect();
        assert_eq!(
            names,
            [
                "c0_12.0__k_cubic",
                "c0_25.0__k_cubic",
                "c0_50.0__k_cubic",
                "c0_12.0__k_gauss"
            ]
        );
        let raw: Vec<&str> = cases[3].overrides.iter().map(|o| o.raw.as_str()).collect();
        assert_eq!(
            raw,
            [
                "end_time=1.0",
                "fluid.sound_speed=12.0",
                "kernel=Gaussian",
                "h_over_dx=0.9"
            ]
        );
    }

    #[test]
    fn fallback_runs_append_their_overrides_and_name_their_scheme() {
        let text = r#"Study(name: "s", scenario: "x.ron", set: ["end_time=1.0"],
            parameters: [(name: "c0", path: "fluid.sound_speed", values: ["12.0", "25.0"])],
            fallback: (label: "fourtakas", set: ["pipeline.reinitialise.every=1000000000"]))"#;
        let spec: StudySpec = parse_ron(text, "s.ron").unwrap_or_else(|e| panic!("{e}"));
        let cases = cases(&spec, "s.ron", &[]).unwrap();
        assert!(cases.iter().all(|c| c.scheme.as_deref() == Some("paper")));
        let fallbacks = fallback_cases(&spec, "s.ron", text, &cases).unwrap();
        assert_eq!(fallbacks.len(), 2);
        let f = &fallbacks[1];
        assert_eq!(f.name, "c0_25.0__fourtakas");
        assert_eq!(f.legend(), "c0_25.0 (fourtakas)");
        assert_eq!(cases[1].legend(), "c0_25.0");
        assert_eq!((f.scheme.as_deref(), f.fallback), (Some("fourtakas"), true));
        let raw: Vec<&str> = f.overrides.iter().map(|o| o.raw.as_str()).collect();
        assert_eq!(
            raw,
            [
                "end_time=1.0",
                "fluid.sound_speed=25.0",
                "pipeline.reinitialise.every=1000000000"
            ]
        );
        // No fallback field: no scheme, no fallback runs.
        let plain = spec_without_fallback();
        let c = super::cases(&plain, "s.ron", &[]).unwrap();
        assert!(c.iter().all(|c| c.scheme.is_none()));
        assert!(fallback_cases(&plain, "s.ron", "", &c).unwrap().is_empty());
        // The same name for both schemes is refused, at the label.
        let same = text.replace("label: \"fourtakas\"", "label: \"paper\"");
        let spec: StudySpec = parse_ron(&same, "s.ron").unwrap();
        let e = fallback_cases(&spec, "s.ron", &same, &cases).unwrap_err();
        assert_eq!((e.line, e.field.as_deref()), (3, Some("fallback.label")));
    }

    #[test]
    fn a_fallback_folder_that_is_a_case_folder_is_refused() {
        let text = r#"Study(name: "s", scenario: "x.ron",
            parameters: [(name: "a", path: "end_time", values: ["1.0", "2.0"], labels: ["x", "x__f"])],
            fallback: (label: "f", set: ["end_time=3.0"]))"#;
        let spec: StudySpec = parse_ron(text, "s.ron").unwrap_or_else(|e| panic!("{e}"));
        let cases = cases(&spec, "s.ron", &[]).unwrap();
        let e = fallback_cases(&spec, "s.ron", text, &cases).unwrap_err();
        assert!(e.to_string().contains("`a_x__f` is also a case's"), "{e}");
        assert_eq!(e.line, 3);
    }

    fn spec_without_fallback() -> StudySpec {
        spec("OneAtATime", r#""1.3", "0.9""#)
    }

    #[test]
    fn locate_finds_a_field_not_a_path_containing_its_name() {
        let text = "Study(\n  scenario: \"/x/fallback/a.ron\",\n  fallback : (set: [\"a\"]),\n)";
        assert_eq!(locate(text, "fallback"), (3, 3));
        assert_eq!(locate(text, "\"a\""), (3, 21));
        assert_eq!(locate(text, "missing"), (1, 1));
    }

    #[test]
    fn grid_takes_every_combination_and_linked_values_must_match() {
        let cases = cases(&spec("Grid", r#""1.3", "0.9""#), "s.ron", &[]).unwrap();
        assert_eq!(cases.len(), 6);
        assert_eq!(cases[5].name, "c0_50.0__k_gauss");
        let e = super::cases(&spec("Grid", r#""1.3""#), "s.ron", &[]).unwrap_err();
        assert_eq!(e.field.as_deref(), Some("linked"));
        assert!(e.to_string().contains("has 1 values for 2"), "{e}");
    }

    /// `--case K` by number (1-based) or folder name; anything else is refused with
    /// the study's name, its case count and, for a name, the names it has.
    #[test]
    fn find_case_takes_a_number_or_a_name() {
        let s = spec("Grid", r#""1.3", "0.9""#);
        let study = Study {
            cases: cases(&s, "s.ron", &[]).unwrap(),
            spec: s,
            file: "s.ron".into(),
            scenario: "x.ron".into(),
            fallbacks: Vec::new(),
        };
        assert_eq!(find_case(&study, "1").unwrap(), 0);
        assert_eq!(find_case(&study, " 6 ").unwrap(), 5);
        assert_eq!(find_case(&study, "c0_50.0__k_gauss").unwrap(), 5);
        let e = find_case(&study, "7").unwrap_err();
        assert!(
            matches!(
                &e,
                StudyError::NoCase {
                    count: 6,
                    names: None,
                    ..
                }
            ),
            "{e}"
        );
        assert!(
            e.to_string()
                .starts_with("--case 7: study s has cases 1 to 6"),
            "{e}"
        );
        let e = find_case(&study, "c0_99").unwrap_err();
        assert!(
            matches!(&e, StudyError::NoCase { names: Some(n), .. } if n.len() == 6),
            "{e}"
        );
        assert!(e.to_string().contains("c0_12.0__k_cubic"), "{e}");
    }
}
