//! The WCSPH scenario format: the RON schema, the loader with its validation and
//! `file:line:column` errors, the pipeline's contract check, and command-line `--set`
//! overrides applied to the text. One RON lexer (`lexer`) serves the overrides
//! (strict) and the loader's error positions (lenient).

mod lexer;
pub mod overrides;
pub mod scenario;

pub use scenario::{dimensions_of, LoadError, Scenario};
