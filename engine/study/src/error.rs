//! Why a study, a sweep or a wave analysis could not be done: each refusal with what it
//! needs as data, shown as a message naming the file, case or field.

use sph_output::plot::PlotError;
use sph_run::runner::RunError;
use sph_scenario::LoadError;
use std::path::{Path, PathBuf};

#[derive(Debug, thiserror::Error)]
pub enum StudyError {
    /// A file or folder could not be read, written or parsed.
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
    /// A series file lacks a column.
    #[error("{}: no column `{column}` (columns: {})", path.display(), columns.join(", "))]
    NoColumn {
        path: PathBuf,
        column: String,
        columns: Vec<String>,
    },
    /// A series lacks what an analysis reads from it; `hint` says which stage or
    /// scenario field writes it.
    #[error("{error}; {hint}")]
    Missing {
        error: Box<StudyError>,
        hint: &'static str,
    },
    /// Too few samples in a fitting window.
    #[error("{}: too few samples of {what} in {from}..{to} s", path.display())]
    TooFewSamples {
        path: PathBuf,
        what: String,
        from: f64,
        to: f64,
    },
    /// The scenario (or the study's) is refused.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// A run failed other than by going unstable.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A run went unstable; its outputs are kept.
    #[error("{error} (outputs in {})", dir.display())]
    Unstable {
        error: sph_core::StepError,
        dir: PathBuf,
    },
    /// A figure could not be drawn.
    #[error(transparent)]
    Plot(#[from] PlotError),
    /// A case's `--set` override could not be written.
    #[error(transparent)]
    Override(#[from] sph_scenario::overrides::OverrideError),
    /// A sweep's scenario lacks what a sweep needs.
    #[error("{0}")]
    NotASweep(&'static str),
    /// `--case K` names no case of the study.
    #[error("--case {given}: {}", match names {
        None => format!("study {study} has cases 1 to {count}"),
        Some(names) => format!(
            "no case of study {study} has that number or name; its cases are 1 to {count}: {}",
            names.join(", ")
        ),
    })]
    NoCase {
        given: String,
        study: String,
        count: usize,
        /// The cases' names, when `given` is not a number.
        names: Option<Vec<String>>,
    },
    /// Some cases of a sweep failed; the others were written.
    #[error("{} of {total} cases failed (the others are in response.csv):\n{}", failures.len(), failures.iter().map(|e| e.to_string()).collect::<Vec<_>>().join("\n"))]
    CasesFailed {
        total: usize,
        failures: Vec<StudyError>,
    },
    /// A case was not run (a report of finished cases only).
    #[error("not run")]
    NotRun,
}

impl StudyError {
    /// A file error at `path`.
    pub fn file(path: &Path, e: impl std::fmt::Display) -> Self {
        Self::File {
            path: path.to_path_buf(),
            message: e.to_string(),
        }
    }
}
