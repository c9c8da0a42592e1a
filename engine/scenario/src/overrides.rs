//! Command-line `--set path=value` overrides of a RON scenario, applied to its text.
//!
//! Patching the text (rather than a parsed value tree) keeps the loader's line:column error
//! positions meaningful and preserves the names of enum-like pipeline entries such as
//! `Reinitialise(every: 5)`, which a generic RON value tree would drop. Each patch's
//! place in the patched text is kept ([`Patch`]), so the loader can name the `--set`
//! argument an error comes from instead of a place in the file.

mod tree;
pub(crate) use tree::*;

use crate::lexer::{lex, Shape, SyntaxError, Tok, Token};
use sph_core::registry::{did_you_mean, snake_case};
use std::ops::Range;
use std::str::FromStr;

/// Deepest bracket nesting accepted, so that hostile input cannot overflow the stack.
const MAX_DEPTH: usize = 128;

/// One `--set path=value` from the command line.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Override {
    /// Dot-separated segments: field names, list indices, snake_case element names or map keys.
    pub path: Vec<String>,
    /// RON text that replaces (or is inserted as) the selected value.
    pub value: String,
    /// The argument as given, for error messages.
    pub raw: String,
}

/// Why an override could not be parsed or applied.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum OverrideError {
    /// The argument is not `path=value`, or its value is not a single RON value.
    #[error("--set {raw}: {reason}")]
    Syntax { raw: String, reason: String },
    /// The path does not select anything in the scenario.
    #[error("--set {raw}: {reason}")]
    Path { raw: String, reason: String },
    /// The scenario text is not well-formed RON.
    #[error("--set {raw}: cannot patch the scenario, malformed at {line}:{column}: {reason}")]
    Malformed {
        raw: String,
        line: usize,
        column: usize,
        reason: String,
    },
}

impl FromStr for Override {
    type Err = OverrideError;

    /// Parses `a.b.c=value`; whitespace around the path segments and the value is ignored.
    fn from_str(raw: &str) -> Result<Self, Self::Err> {
        let Some((path, value)) = raw.split_once('=') else {
            return Err(OverrideError::Syntax {
                raw: raw.to_owned(),
                reason:
                    "expected `path=value`, e.g. `end_time=0.5` or `pipeline.reinitialise.every=5`"
                        .to_owned(),
            });
        };
        let parsed = Self {
            path: path.split('.').map(|s| s.trim().to_owned()).collect(),
            value: value.trim().to_owned(),
            raw: raw.to_owned(),
        };
        parsed.check()?;
        Ok(parsed)
    }
}

impl Override {
    /// Rejects empty path segments and values that are not exactly one RON value.
    fn check(&self) -> Result<(), OverrideError> {
        let reason = if self.path.iter().all(|s| !s.is_empty()) && !self.path.is_empty() {
            match single_value(&self.value) {
                Ok(()) => return Ok(()),
                Err(e) => format!(
                    "value `{}` is not a single RON value: {}",
                    self.value, e.reason
                ),
            }
        } else {
            "empty path segment".to_owned()
        };
        Err(OverrideError::Syntax {
            raw: self.raw.clone(),
            reason,
        })
    }
}

/// Where one override landed in the patched text (byte ranges of the final text).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Patch {
    /// The `--set` argument as given.
    pub raw: String,
    /// The text the override wrote: the new value, or `name: value, ` when inserted.
    pub span: Range<usize>,
    /// Each segment of the path that is not a list index, with the struct, list or map
    /// that holds it: for `pipeline.integrate.courant`, `pipeline` in the scenario,
    /// `integrate` in the list, `courant` in `Integrate(...)`.
    pub holders: Vec<(String, Range<usize>)>,
    /// The length of the text it replaced (0 when inserted); for a patch that no
    /// other patch holds, text of the file.
    pub replaced: usize,
}

impl Patch {
    /// The field (or element) the override sets: its last segment that is not a list
    /// index, e.g. `courant`, or `gravity` for `gravity.1`.
    pub fn field(&self) -> Option<&str> {
        self.holders.last().map(|(s, _)| s.as_str())
    }
}

/// The offset in the file of `offset` in the patched text, when that lies outside
/// every patch: moved back by what the patches before it added or removed.
pub fn source_offset(offset: usize, patches: &[Patch]) -> usize {
    let outermost = patches.iter().filter(|p| {
        !patches
            .iter()
            .any(|q| q.span != p.span && q.span.start <= p.span.start && p.span.end <= q.span.end)
    });
    let before = outermost.filter(|p| p.span.end <= offset);
    let (added, removed) = before.fold((0, 0), |(a, r), p| (a + p.span.len(), r + p.replaced));
    (offset + removed).saturating_sub(added)
}

/// `r` after an edit that replaced the text at `edit` by `len` bytes: unchanged before
/// it, moved after it, grown around it; `None` when the edit overwrote (part of) it.
fn shifted(r: &Range<usize>, edit: &Range<usize>, len: usize) -> Option<Range<usize>> {
    if r.end <= edit.start {
        Some(r.clone())
    } else if r.start >= edit.end {
        Some(r.start - edit.len() + len..r.end - edit.len() + len)
    } else if edit.start <= r.start && r.end <= edit.end {
        None
    } else if r.start <= edit.start && edit.end <= r.end {
        Some(r.start..r.end - edit.len() + len)
    } else {
        None
    }
}

/// Applies overrides in order; returns the patched RON text.
pub fn apply_overrides(source: &str, overrides: &[Override]) -> Result<String, OverrideError> {
    apply_overrides_traced(source, overrides).map(|(text, _)| text)
}

/// As [`apply_overrides`], with where each override landed in the patched text (the
/// ones a later override overwrote left out).
pub fn apply_overrides_traced(
    source: &str,
    overrides: &[Override],
) -> Result<(String, Vec<Patch>), OverrideError> {
    let mut text = source.to_owned();
    let mut patches: Vec<Patch> = Vec::new();
    for ov in overrides {
        ov.check()?;
        let root = document(&text).map_err(|e| e.locate(&text, &ov.raw))?;
        let (range, replacement, holders) =
            resolve(&text, &root, ov).map_err(|e| OverrideError::Path {
                raw: ov.raw.clone(),
                reason: e.to_string(),
            })?;
        let len = replacement.len();
        text.replace_range(range.clone(), &replacement);
        patches.retain_mut(|p| {
            let Some(span) = shifted(&p.span, &range, len) else {
                return false;
            };
            p.span = span;
            p.holders
                .iter_mut()
                .all(|(_, r)| shifted(r, &range, len).map(|s| *r = s).is_some())
        });
        let span = range.start..range.start + len;
        let holders = ov
            .path
            .iter()
            .zip(holders)
            .filter(|(seg, _)| seg.parse::<usize>().is_err())
            .map(|(seg, r)| {
                (
                    seg.clone(),
                    shifted(&r, &range, len).unwrap_or(span.clone()),
                )
            })
            .collect();
        patches.push(Patch {
            raw: ov.raw.clone(),
            span,
            holders,
            replaced: range.len(),
        });
    }
    Ok((text, patches))
}

impl Shape {
    /// What one entry is called in messages.
    fn item(self) -> &'static str {
        match self {
            Shape::Struct => "field",
            Shape::List => "element",
            Shape::Map => "key",
        }
    }
}

impl SyntaxError {
    /// Converts the byte offset into a 1-based line:column (columns count characters).
    fn locate(self, text: &str, raw: &str) -> OverrideError {
        let before = &text.as_bytes()[..self.at.min(text.len())];
        let line_start = before
            .iter()
            .rposition(|&b| b == b'\n')
            .map_or(0, |p| p + 1);
        OverrideError::Malformed {
            raw: raw.to_owned(),
            line: before.iter().filter(|&&b| b == b'\n').count() + 1,
            column: before[line_start..]
                .iter()
                .filter(|&&b| b & 0xC0 != 0x80)
                .count()
                + 1,
            reason: self.reason,
        }
    }
}

#[cfg(test)]
mod tests;
